/* dist.c — data-parallel collectives over MPI, or a single rank (dist.h). */
#include <stdlib.h>
#include <string.h>
#include "train/dist.h"
#ifdef LM_HAVE_MPI
#include <mpi.h>
#endif

static int g_init, g_rank, g_size = 1;
static double g_comm;

int lm_dist_available(void)
{
#ifdef LM_HAVE_MPI
    return 1;
#else
    return 0;
#endif
}

#ifdef LM_HAVE_MPI
/* Started by an MPI launcher? (Open MPI, MPICH/Hydra, PMIx-based launchers.) */
static int launched(void)
{
    static const char *const vars[] = {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", NULL};
    for (int i = 0; vars[i]; i++)
        if (getenv(vars[i])) return 1;
    return 0;
}
#endif

int lm_dist_init(int *argc, char ***argv)
{
    if (g_init) return g_size;
    g_init = 1;
#ifdef LM_HAVE_MPI
    int flag = 0;
    MPI_Initialized(&flag);
    if (!flag && launched()) {
        MPI_Init(argc, argv);
        atexit(lm_dist_finalize);
        flag = 1;
    }
    if (flag) {
        MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
        MPI_Comm_size(MPI_COMM_WORLD, &g_size);
    }
#else
    (void)argc, (void)argv;
#endif
    return g_size;
}

void lm_dist_finalize(void)
{
#ifdef LM_HAVE_MPI
    int init = 0, done = 0;
    MPI_Initialized(&init);
    MPI_Finalized(&done);
    if (init && !done) MPI_Finalize();
#endif
}

int lm_dist_rank(void) { return g_rank; }
int lm_dist_size(void) { return g_size; }
double lm_dist_comm_seconds(void) { return g_comm; }

void lm_dist_sum_float(float *x, size_t n)
{
#ifdef LM_HAVE_MPI
    if (g_size < 2) return;
    double t0 = MPI_Wtime();
    for (size_t off = 0; off < n;) { /* counts are ints: chunks of at most 2^30 */
        int k = n - off > (1u << 30) ? (1 << 30) : (int)(n - off);
        MPI_Allreduce(MPI_IN_PLACE, x + off, k, MPI_FLOAT, MPI_SUM, MPI_COMM_WORLD);
        off += (size_t)k;
    }
    g_comm += MPI_Wtime() - t0;
#else
    (void)x, (void)n;
#endif
}

void lm_dist_sum_double(double *x, size_t n)
{
#ifdef LM_HAVE_MPI
    if (g_size > 1) MPI_Allreduce(MPI_IN_PLACE, x, (int)n, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
#else
    (void)x, (void)n;
#endif
}

void lm_dist_max_long(long *x, size_t n)
{
#ifdef LM_HAVE_MPI
    if (g_size > 1) MPI_Allreduce(MPI_IN_PLACE, x, (int)n, MPI_LONG, MPI_MAX, MPI_COMM_WORLD);
#else
    (void)x, (void)n;
#endif
}

void lm_dist_bcast_long(long *x, size_t n)
{
#ifdef LM_HAVE_MPI
    if (g_size > 1) MPI_Bcast(x, (int)n, MPI_LONG, 0, MPI_COMM_WORLD);
#else
    (void)x, (void)n;
#endif
}

void lm_dist_barrier(void)
{
#ifdef LM_HAVE_MPI
    if (g_size > 1) MPI_Barrier(MPI_COMM_WORLD);
#endif
}
