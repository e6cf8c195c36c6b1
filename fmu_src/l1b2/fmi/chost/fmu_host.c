/*
 * fmu_host.c - a minimal FMI 2.0 co-simulation host in C for the l1b2 FMUs
 * (PythonFMU 0.7.0 binaries), written to show and test what a non-Python host
 * needs. Linux only.
 *
 * usage: fmu_host [options] <extracted-fmu-dir> <modelIdentifier> <guid>
 *   -L <libpython>   shared libpython to dlopen(RTLD_NOW|RTLD_GLOBAL) before the FMU
 *                    (default: $L1B2_LIBPYTHON; "-" = do not load one, e.g. with LD_PRELOAD)
 *   -h <step>        communication step [s]            (default 2e-4)
 *   -n <steps>       number of steps                   (default 10)
 *   -p <vr>=<value>  Real parameter / start value, set before initialisation (repeatable)
 *   -b <vr>=<0|1>    Boolean parameter, set before initialisation (repeatable)
 *   -i <vr>=<value>  Real input, set before initialisation and before every step (repeatable)
 *   -o <vr>          Real to print after initialisation and after every step (repeatable)
 *   -e <k>           print (and read the outputs) only at every k-th communication point and the last
 *                    (default 1: every point)
 *   -T <0|1>         1: time the stepping loop (set inputs, doStep, read outputs at the output points) and
 *                    print "fmu_host: timing <steps> <wall s> <CPU s of the process>" on stderr
 *   -x <mode>        exit: "finalize" (default) calls the library's finalizePythonInterpreter()
 *                    after fmi2FreeInstance; "plain" just returns from main (shows the
 *                    PythonFMU 0.7.0 exit-time use-after-free)
 *
 * output (stdout): one line per communication point, "time value..." with %.17g.
 * exit code: 0 = every FMI call returned fmi2OK/fmi2Warning; 2 usage; 3 loading;
 *            4 instantiation; 10 + status for a failing FMI call.
 *
 * environment: PYTHONPATH must name a site-packages with numpy and scipy (the
 * FMU's code imports them); PYTHONHOME must not be set to a virtual environment.
 *
 * build: gcc -O2 -Wall -std=c99 -I<fmpy>/c-code -o fmu_host fmu_host.c -ldl
 *        (<fmpy> = python -c "import fmpy, os; print(os.path.dirname(fmpy.__file__))")
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <time.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define MAXV 256

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s][status %d][%s] ", instance ? instance : "?", (int)status, category ? category : "");
    vfprintf(stderr, message, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static int parse_assignment(const char* arg, fmi2ValueReference* vr, double* value)
{
    char* end;
    unsigned long r = strtoul(arg, &end, 10);
    if (end == arg || *end != '=') return -1;
    *vr = (fmi2ValueReference)r;
    *value = strtod(end + 1, &end);
    return *end == '\0' ? 0 : -1;
}

static void* sym(void* lib, const char* name)
{
    void* f = dlsym(lib, name);
    if (!f) fprintf(stderr, "fmu_host: dlsym %s: %s\n", name, dlerror());
    return f;
}

#define CHECK(call)                                                                      \
    do {                                                                                 \
        fmi2Status s_ = (call);                                                          \
        if (s_ > fmi2Warning) {                                                          \
            fprintf(stderr, "fmu_host: %s returned status %d\n", #call, (int)s_);       \
            rc = 10 + (int)s_;                                                           \
            goto done;                                                                   \
        }                                                                                \
    } while (0)

int main(int argc, char** argv)
{
    const char* libpython = getenv("L1B2_LIBPYTHON");
    const char* exit_mode = "finalize";
    double h = 2e-4;
    long nsteps = 10;
    long every = 1;
    int timing = 0;
    fmi2ValueReference pvr[MAXV], bvr[MAXV], ivr[MAXV], ovr[MAXV];
    double pval[MAXV], ival[MAXV], out[MAXV];
    fmi2Boolean bval[MAXV];
    int np = 0, nb = 0, ni = 0, no = 0;
    int a = 1;
    for (; a < argc && argv[a][0] == '-' && argv[a][1] != '\0' && argv[a][2] == '\0'; a += 2) {
        char opt = argv[a][1];
        if (a + 1 >= argc) { fprintf(stderr, "fmu_host: option -%c needs a value\n", opt); return 2; }
        const char* v = argv[a + 1];
        double x;
        fmi2ValueReference r;
        switch (opt) {
        case 'L': libpython = v; break;
        case 'h': h = atof(v); break;
        case 'n': nsteps = atol(v); break;
        case 'x': exit_mode = v; break;
        case 'e': every = atol(v); break;
        case 'T': timing = atoi(v); break;
        case 'p': case 'b': case 'i':
            if (parse_assignment(v, &r, &x) != 0 || np >= MAXV || nb >= MAXV || ni >= MAXV) {
                fprintf(stderr, "fmu_host: bad assignment '%s' (expected vr=value)\n", v);
                return 2;
            }
            if (opt == 'p') { pvr[np] = r; pval[np++] = x; }
            else if (opt == 'b') { bvr[nb] = r; bval[nb++] = x != 0.0 ? fmi2True : fmi2False; }
            else { ivr[ni] = r; ival[ni++] = x; }
            break;
        case 'o':
            if (no >= MAXV) return 2;
            ovr[no++] = (fmi2ValueReference)strtoul(v, NULL, 10);
            break;
        default: fprintf(stderr, "fmu_host: unknown option -%c\n", opt); return 2;
        }
    }
    if (argc - a != 3 || !(h > 0.0) || nsteps < 0 || every < 1) {
        fprintf(stderr, "usage: %s [-L libpython] [-h step] [-n steps] [-p vr=x].. [-b vr=0|1].. "
                        "[-i vr=x].. [-o vr].. [-e k] [-T 0|1] [-x finalize|plain] <fmu-dir> <modelIdentifier> "
                        "<guid>\n", argv[0]);
        return 2;
    }
    const char* dir = argv[a];
    const char* model_identifier = argv[a + 1];
    const char* guid = argv[a + 2];

    /* 1. libpython first, with global symbols: the FMU binary uses Py* symbols but does not link it */
    if (libpython && strcmp(libpython, "-") != 0) {
        if (!dlopen(libpython, RTLD_NOW | RTLD_GLOBAL)) {
            fprintf(stderr, "fmu_host: dlopen libpython: %s\n", dlerror());
            return 3;
        }
    }

    /* 2. the FMU library, by absolute path */
    char absdir[PATH_MAX], so[PATH_MAX + 128], uri[3 * PATH_MAX + 32];
    if (!realpath(dir, absdir)) { perror("fmu_host: realpath"); return 3; }
    snprintf(so, sizeof so, "%s/binaries/linux64/%s.so", absdir, model_identifier);
    void* lib = dlopen(so, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "fmu_host: dlopen FMU: %s\n", dlerror()); return 3; }

    fmi2InstantiateTYPE* instantiate = (fmi2InstantiateTYPE*)sym(lib, "fmi2Instantiate");
    fmi2FreeInstanceTYPE* free_instance = (fmi2FreeInstanceTYPE*)sym(lib, "fmi2FreeInstance");
    fmi2SetupExperimentTYPE* setup = (fmi2SetupExperimentTYPE*)sym(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE* enter = (fmi2EnterInitializationModeTYPE*)sym(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE* exit_init = (fmi2ExitInitializationModeTYPE*)sym(lib, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE* set_real = (fmi2SetRealTYPE*)sym(lib, "fmi2SetReal");
    fmi2SetBooleanTYPE* set_boolean = (fmi2SetBooleanTYPE*)sym(lib, "fmi2SetBoolean");
    fmi2GetRealTYPE* get_real = (fmi2GetRealTYPE*)sym(lib, "fmi2GetReal");
    fmi2DoStepTYPE* do_step = (fmi2DoStepTYPE*)sym(lib, "fmi2DoStep");
    fmi2TerminateTYPE* terminate = (fmi2TerminateTYPE*)sym(lib, "fmi2Terminate");
    if (!instantiate || !free_instance || !setup || !enter || !exit_init || !set_real || !set_boolean
        || !get_real || !do_step || !terminate)
        return 3;

    /* 3. resource location: file:// URI of the resources folder (spaces as %20, as PythonFMU decodes) */
    char* u = uri + snprintf(uri, sizeof uri, "file://");
    for (const char* c = absdir; *c; c++) {
        if (*c == ' ') { memcpy(u, "%20", 3); u += 3; } else *u++ = *c;
    }
    strcpy(u, "/resources");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("fmu_host", fmi2CoSimulation, guid, uri, &callbacks, fmi2False, fmi2False);
    if (!c) { fprintf(stderr, "fmu_host: fmi2Instantiate failed\n"); return 4; }

    int rc = 0;
    double t = 0.0;
    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    if (np) CHECK(set_real(c, pvr, np, pval));
    if (nb) CHECK(set_boolean(c, bvr, nb, bval));
    if (ni) CHECK(set_real(c, ivr, ni, ival));
    CHECK(enter(c));
    CHECK(exit_init(c));
    struct timespec w0, w1, c0, c1;
    clock_gettime(CLOCK_MONOTONIC, &w0);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
    for (long k = 0; k <= nsteps; k++) {
        if (k > 0) {
            if (ni) CHECK(set_real(c, ivr, ni, ival));
            CHECK(do_step(c, t, h, fmi2True));
            t = k * h;
        }
        if (k % every != 0 && k != nsteps) continue;
        if (no) CHECK(get_real(c, ovr, no, out));
        printf("%.17g", t);
        for (int j = 0; j < no; j++) printf(" %.17g", out[j]);
        printf("\n");
    }
    clock_gettime(CLOCK_MONOTONIC, &w1);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
    if (timing)
        fprintf(stderr, "fmu_host: timing %ld %.9f %.9f\n", nsteps,
                (double)(w1.tv_sec - w0.tv_sec) + 1e-9 * (double)(w1.tv_nsec - w0.tv_nsec),
                (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec));
    CHECK(terminate(c));
done:
    free_instance(c);
    fflush(stdout);
    fflush(stderr);
    /* 4. PythonFMU 0.7.0: empty its static PyState pointer while it is alive (and, since this process
     *    let the FMU start Python, finalize the interpreter on its own thread). Without this the
     *    library's exit-time destructors release the pointer twice and the process aborts. */
    if (strcmp(exit_mode, "finalize") == 0) {
        void (*finalize)(void) = (void (*)(void))dlsym(lib, "finalizePythonInterpreter");
        if (finalize) finalize();
    }
    /* no dlclose: the library is never unloaded anyway (STB_GNU_UNIQUE symbols) */
    return rc;
}
