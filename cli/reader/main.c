/* lumosaic-reader — the helper program in which lumosaic reads .mat files (data/isolate.h).
 * What it is: a small executable linked with the .mat reader and only the libraries it needs
 * (matio, HDF5), so a child starts in milliseconds rather than in the fraction of a second the
 * full program takes to load its image libraries. The reader runs from a constructor before
 * main (LM_ISOLATE_ENTRY in data/io_mat.c) when lumosaic starts it; main is reached only when
 * someone runs the helper by hand.
 * What it is not: a command for users. */
#include "data/cube_io.h"
#include <stdio.h>

int main(void)
{
    fprintf(stderr, "lumosaic-reader: a helper that lumosaic starts to read '%s' files in a "
                    "separate process; not a command to run by hand\n", lm_mat_reader_name());
    return 2;
}
