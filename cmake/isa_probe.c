/* isa_probe.c — prints the best instruction-set level of the machine that configures the build
 * (tensor/isa.c's own detection), so that the per-level tests are registered only for levels
 * this machine can run (CMakeLists.txt, label "isa"). */
#include <stdio.h>
#include "tensor/isa.h"

int main(void)
{
    printf("%s", lm_isa_name(lm_isa_best()));
    return 0;
}
