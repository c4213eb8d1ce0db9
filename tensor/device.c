/* device.c — the backend registry of device.h: "cpu" built in, device backends registered by
 * name (kernels-opencl/ registers "opencl"), opened and closed through the backend interface.
 * Not here: the transfers (transfer.c), the parameter swaps (mirror.c), a backend itself. */
#include "tensor/device.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_BACKENDS 8

/* Filled at start-up (before main, by the backends' constructors), read afterwards. */
static struct {
    const char *name;
    lm_backend_open_fn open;
} registry[MAX_BACKENDS];
static int nregistered;

void lm_backend_register(const char *name, lm_backend_open_fn open)
{
    if (!name || !open || nregistered == MAX_BACKENDS) return;
    for (int i = 0; i < nregistered; i++)
        if (!strcmp(registry[i].name, name)) return;
    registry[nregistered].name = name;
    registry[nregistered].open = open;
    nregistered++;
}

lm_backend *lm_backend_open(const char *name, lm_err *e)
{
    if (!name || !*name) name = getenv("LM_DEVICE");
    if (!name || !*name || !strcmp(name, "cpu")) return lm_backend_cpu();
    for (int i = 0; i < nregistered; i++)
        if (!strcmp(registry[i].name, name)) return registry[i].open(e);
    char known[256] = "cpu";
    for (int i = 0; i < nregistered; i++) {
        size_t k = strlen(known);
        snprintf(known + k, sizeof known - k, "%s%s", i + 1 == nregistered ? " or " : ", ",
                 registry[i].name);
    }
    lm_err_set(e, LM_ERR_ARG, "unknown device '%s' (expected %s)", name, known);
    return NULL;
}

void lm_backend_close(lm_backend *b)
{
    if (b && b->close) b->close(b);
}

const char *lm_backend_device_name(const lm_backend *b)
{
    return b && b->device_name ? b->device_name : "";
}
