/*
 * rtf_host.c - the smallest FMI 2.0 co-simulation host that times an FMU's steps (bench/bench_native.py).
 *
 * usage: rtf_host <extracted-fmu-dir> <modelIdentifier> <guid> <step> <n> [vr=value ...] -- [out-vr ...]
 *   vr=value: Real parameters and inputs set before initialisation; out-vr: Reals read after every step.
 * prints: "<wall seconds> <CPU seconds of the process> of the n doStep+getReal calls, then the last value of each
 *          output"; exit 1 on any failure.
 * build: cc -O2 -std=c99 -I<fmpy>/c-code -o rtf_host rtf_host.c -ldl
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment e, fmi2String name, fmi2Status s, fmi2String cat, fmi2String msg, ...)
{
    (void)e; (void)cat;
    fprintf(stderr, "[%s][%d] %s\n", name ? name : "?", (int)s, msg);
}

static void* sym(void* lib, const char* name)
{
    void* f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "rtf_host: %s missing\n", name);
        exit(1);
    }
    return f;
}

int main(int argc, char** argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s <dir> <modelIdentifier> <guid> <step> <n> [vr=value ...] -- [out-vr ...]\n",
                argv[0]);
        return 2;
    }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "rtf_host: %s\n", dlerror());
        return 1;
    }
    fmi2InstantiateTYPE* instantiate = (fmi2InstantiateTYPE*)sym(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE* setup = (fmi2SetupExperimentTYPE*)sym(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE* enter = (fmi2EnterInitializationModeTYPE*)sym(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE* exitinit = (fmi2ExitInitializationModeTYPE*)sym(lib, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE* set_real = (fmi2SetRealTYPE*)sym(lib, "fmi2SetReal");
    fmi2GetRealTYPE* get_real = (fmi2GetRealTYPE*)sym(lib, "fmi2GetReal");
    fmi2DoStepTYPE* do_step = (fmi2DoStepTYPE*)sym(lib, "fmi2DoStep");
    fmi2FreeInstanceTYPE* free_instance = (fmi2FreeInstanceTYPE*)sym(lib, "fmi2FreeInstance");
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("rtf", fmi2CoSimulation, argv[3], uri, &cb, fmi2False, fmi2False);
    if (!c) return 1;
    double h = atof(argv[4]);
    long n = atol(argv[5]);
    fmi2ValueReference out[64];
    size_t n_out = 0;
    int i = 6;
    for (; i < argc && strcmp(argv[i], "--") != 0; i++) {
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[i], NULL, 10);
        double x = atof(strchr(argv[i], '=') + 1);
        if (set_real(c, &vr, 1, &x) > fmi2Warning) return 1;
    }
    for (i++; i < argc && n_out < 64; i++) out[n_out++] = (fmi2ValueReference)strtoul(argv[i], NULL, 10);
    if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning || enter(c) > fmi2Warning
        || exitinit(c) > fmi2Warning)
        return 1;
    double values[64];
    struct timespec t0, t1, c0, c1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
    for (long k = 0; k < n; k++) {
        if (do_step(c, k * h, h, fmi2True) > fmi2Warning || get_real(c, out, n_out, values) > fmi2Warning) {
            fprintf(stderr, "rtf_host: step %ld failed\n", k);
            return 1;
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
    printf("%.9f %.9f", (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec),
           (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec));
    for (size_t j = 0; j < n_out; j++) printf(" %.17g", values[j]);
    printf("\n");
    free_instance(c);
    return 0;
}
