/* dist.h — data-parallel training across processes (MPI), and nothing when there is one.
 * What it is: the few collective operations the training loop, validation and the study need
 * (start-up, rank and size, sum/max of small buffers, the gradient average, a broadcast), on
 * MPI_COMM_WORLD when the program was built with MPI (LM_HAVE_MPI, CMake's FindMPI) and
 * started by mpirun/mpiexec (detected from the launcher's environment: OMPI_COMM_WORLD_SIZE,
 * PMI_SIZE, PMIX_RANK); otherwise one rank of one, and every call does nothing, so a program
 * run without mpirun behaves exactly as one built without MPI.
 * Errors: MPI's default handler (MPI_ERRORS_ARE_FATAL) stays: a rank that dies or fails a
 * collective ends the whole job (mpirun reports which rank), rather than leaving the others
 * waiting.
 * What it is not: a transport of our own, or model/dataset sharding (every rank holds the whole
 * model; ranks differ only in the samples they draw). */
#ifndef LM_DIST_H
#define LM_DIST_H
#include <stddef.h>

/* Start (once; later calls do nothing). Returns the number of ranks. Call before threads. */
int lm_dist_init(int *argc, char ***argv);
/* Finish (lm_dist_init registers it with atexit as well). */
void lm_dist_finalize(void);
int lm_dist_rank(void);
int lm_dist_size(void);
/* 1 when built with MPI (whether or not started by mpirun). */
int lm_dist_available(void);
/* In place over every rank: x[i] = sum over ranks (floats, doubles), or max (longs). */
void lm_dist_sum_float(float *x, size_t n);
void lm_dist_sum_double(double *x, size_t n);
void lm_dist_max_long(long *x, size_t n);
/* x[0..n) of rank 0 to every rank. */
void lm_dist_bcast_long(long *x, size_t n);
void lm_dist_barrier(void);
/* Seconds spent in lm_dist_sum_float since start (the gradient allreduce), for figures. */
double lm_dist_comm_seconds(void);

#endif
