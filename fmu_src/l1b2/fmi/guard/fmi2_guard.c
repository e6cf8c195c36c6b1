/*
 * fmi2_guard.c - the FMI 2.0 co-simulation entry points of every l1b2 FMU on Linux.
 *
 * The FMU's Python code runs in PythonFMU's native library (shipped beside this
 * one as binaries/linux64/GUARD_INNER). This library is what the host loads
 * (binaries/linux64/<modelIdentifier>.so); it forwards every call to that
 * library after checking what the FMI 2.0 standard lets a host get wrong and
 * PythonFMU 0.7.0 does not check, so that no call sequence crashes or hangs
 * the host:
 *
 *  - fmi2Instantiate: the GUID must be this FMU's, the type co-simulation, the
 *    resources folder must hold the slave module; PythonFMU's library must load
 *    (its dlerror, e.g. libpython missing, reaches the host's logger);
 *  - status: a call during which the FMU logged an error returns fmi2Error
 *    (fmi2Discard for fmi2DoStep) instead of PythonFMU's fmi2OK;
 *  - logging: errors and warnings always reach the host's logger (PythonFMU
 *    drops every message unless debug logging is on), messages are passed as
 *    text, never as a printf format;
 *  - after fmi2Fatal (a Python exception escaped: PythonFMU has released the
 *    Python objects of the instance) the instance refuses every call with
 *    fmi2Error and is never handed back to PythonFMU (freeing it there would
 *    release those objects a second time);
 *  - fmi2DoStep: the communication point must not go backwards;
 *  - FMU states: only states issued by this library are accepted (a state of
 *    another FMU is refused without being read); serialized states carry this
 *    FMU's GUID and are refused otherwise.
 *
 * Compile-time definitions (l1b2.fmi.build): GUARD_GUID, GUARD_INNER.
 * build: cc -shared -fPIC -O2 -Wl,-z,nodelete -DGUARD_GUID=... -DGUARD_INNER=... -o <id>.so fmi2_guard.c -ldl
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#ifndef GUARD_GUID
#error "GUARD_GUID must be defined"
#endif
#ifndef GUARD_INNER
#error "GUARD_INNER must be defined"
#endif

typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char* fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef int fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void* (*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void*);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define STATE_MAGIC 0x4c314232u /* "L1B2" */
#define SER_MAGIC "l1b2-fmu-state\n"

typedef struct Guard {
    unsigned magic;
    fmi2Component inner;
    fmi2CallbackFunctions host;   /* the host's callbacks */
    fmi2CallbackFunctions own;    /* given to PythonFMU: our logger, this guard as environment */
    char* name;
    int host_logging;
    int worst;                    /* worst status logged by the FMU during the current call */
    int dead;                     /* PythonFMU returned fmi2Fatal: the instance must not be used or freed */
    int have_time;
    double time;                  /* the next expected communication point */
    struct Guard* next;           /* live instances of this library */
} Guard;

static Guard* live = NULL;        /* a component is used only when listed here (never a freed or foreign pointer) */

static int is_live(const Guard* g)
{
    for (const Guard* q = live; q; q = q->next)
        if (q == g) return 1;
    return 0;
}

typedef struct State {
    unsigned magic;
    fmi2FMUstate inner;
    int have_time;
    double time;
    struct State* next;
} State;

static State* issued = NULL;      /* states issued by this library (never dereferenced unless listed) */
static void* lib = NULL;
static char lib_error[1024];

/* ------------------------------------------------------------------------ */
/* PythonFMU's library                                                        */
/* ------------------------------------------------------------------------ */

#define INNER_FUNCTIONS(X) \
    X(fmi2Instantiate, fmi2Component, (fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*, fmi2Boolean, fmi2Boolean)) \
    X(fmi2FreeInstance, void, (fmi2Component)) \
    X(fmi2SetDebugLogging, fmi2Status, (fmi2Component, fmi2Boolean, size_t, const fmi2String[])) \
    X(fmi2SetupExperiment, fmi2Status, (fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real)) \
    X(fmi2EnterInitializationMode, fmi2Status, (fmi2Component)) \
    X(fmi2ExitInitializationMode, fmi2Status, (fmi2Component)) \
    X(fmi2Terminate, fmi2Status, (fmi2Component)) \
    X(fmi2Reset, fmi2Status, (fmi2Component)) \
    X(fmi2GetReal, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[])) \
    X(fmi2GetInteger, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[])) \
    X(fmi2GetBoolean, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, fmi2Boolean[])) \
    X(fmi2GetString, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, fmi2String[])) \
    X(fmi2SetReal, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[])) \
    X(fmi2SetInteger, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[])) \
    X(fmi2SetBoolean, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2Boolean[])) \
    X(fmi2SetString, fmi2Status, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2String[])) \
    X(fmi2GetFMUstate, fmi2Status, (fmi2Component, fmi2FMUstate*)) \
    X(fmi2SetFMUstate, fmi2Status, (fmi2Component, fmi2FMUstate)) \
    X(fmi2FreeFMUstate, fmi2Status, (fmi2Component, fmi2FMUstate*)) \
    X(fmi2SerializedFMUstateSize, fmi2Status, (fmi2Component, fmi2FMUstate, size_t*)) \
    X(fmi2SerializeFMUstate, fmi2Status, (fmi2Component, fmi2FMUstate, fmi2Byte[], size_t)) \
    X(fmi2DeSerializeFMUstate, fmi2Status, (fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate*)) \
    X(fmi2DoStep, fmi2Status, (fmi2Component, fmi2Real, fmi2Real, fmi2Boolean))

#define DECLARE(name, ret, args) static ret(*p_##name) args = NULL;
INNER_FUNCTIONS(DECLARE)
static void (*p_finalize)(void) = NULL;

static int load_inner(void)
{
    if (lib) return 1;
    Dl_info info;
    if (!dladdr((void*)&load_inner, &info) || !info.dli_fname) {
        snprintf(lib_error, sizeof lib_error, "cannot locate this library (dladdr failed)");
        return 0;
    }
    char path[4096];
    const char* slash = strrchr(info.dli_fname, '/');
    size_t dir = slash ? (size_t)(slash - info.dli_fname) : 0;
    if (dir + strlen(GUARD_INNER) + 2 > sizeof path) {
        snprintf(lib_error, sizeof lib_error, "path of this library too long");
        return 0;
    }
    if (slash) {
        memcpy(path, info.dli_fname, dir);
        path[dir] = '/';
        strcpy(path + dir + 1, GUARD_INNER);
    } else {
        strcpy(path, GUARD_INNER);
    }
    void* h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!h) {
        const char* e = dlerror();
        snprintf(lib_error, sizeof lib_error,
                 "cannot load the FMU's Python runtime %s: %s (the host must load a shared libpython of the "
                 "version this FMU was built with, with global symbols, before the FMU)", path, e ? e : "?");
        return 0;
    }
    int ok = 1;
#define RESOLVE(name, ret, args) \
    if (!(p_##name = (ret(*) args)dlsym(h, #name))) ok = 0;
    INNER_FUNCTIONS(RESOLVE)
    p_finalize = (void (*)(void))dlsym(h, "finalizePythonInterpreter");
    if (!ok) {
        snprintf(lib_error, sizeof lib_error, "%s lacks FMI 2.0 functions", path);
        return 0;
    }
    lib = h;
    return 1;
}

/* ------------------------------------------------------------------------ */
/* logging and status                                                         */
/* ------------------------------------------------------------------------ */

/* the host's logger with ``text`` as the message: a printf format, so '%' is doubled and nothing else is
 * passed (hosts that print the message without formatting it, e.g. fmpy, then show the text itself) */
static void forward(const fmi2CallbackFunctions* cb, fmi2String name, fmi2Status s, fmi2String category,
                    const char* text)
{
    if (!cb || !cb->logger) return;
    char buf[4096];
    size_t k = 0;
    for (const char* p = text ? text : ""; *p && k + 2 < sizeof buf; p++) {
        if (*p == '%') buf[k++] = '%';
        buf[k++] = *p;
    }
    buf[k] = 0;
    cb->logger(cb->componentEnvironment, name ? name : "?", s, category, buf);
}

static void host_log(const fmi2CallbackFunctions* cb, fmi2String name, fmi2Status s, const char* fmt, ...)
{
    char text[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    forward(cb, name, s, s >= fmi2Error ? "logStatusError" : "logAll", text);
}

/* PythonFMU passes each message as the format string with no arguments: forwarded as text */
static void guard_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                         fmi2String message, ...)
{
    Guard* g = (Guard*)env;
    if (!g) return;
    if ((int)status > g->worst) g->worst = (int)status;
    if (status >= fmi2Warning || g->host_logging)
        forward(&g->host, instance ? instance : g->name, status, category, message);
}

static Guard* use(fmi2Component c, const char* call)
{
    Guard* g = (Guard*)c;
    if (!g || !is_live(g) || g->magic != STATE_MAGIC) return NULL;
    if (g->dead) {
        host_log(&g->host, g->name, fmi2Error, "%s refused: the instance failed fatally before (see the log); "
                 "only fmi2FreeInstance is possible", call);
        return NULL;
    }
    g->worst = fmi2OK;
    return g;
}

/* the status of a forwarded call: an error logged during it is an error */
static fmi2Status done(Guard* g, fmi2Status s, fmi2Status on_error)
{
    if (s == fmi2Fatal) {
        g->dead = 1;
        host_log(&g->host, g->name, fmi2Error, "the instance is unusable after a fatal error; it will not be freed "
                 "by the Python runtime (its objects are already released)");
        return fmi2Error;
    }
    if (g->worst >= fmi2Error && s < on_error) return on_error;
    return s;
}

/* ------------------------------------------------------------------------ */
/* FMI 2.0                                                                    */
/* ------------------------------------------------------------------------ */

const char* fmi2GetTypesPlatform(void) { return "default"; }
const char* fmi2GetVersion(void) { return "2.0"; }

void finalizePythonInterpreter(void)
{
    if (lib && p_finalize) p_finalize();
}

static int decode_uri(const char* uri, char* out, size_t n)
{
    const char* p = uri;
    if (strncmp(p, "file://", 7) == 0) {
        p += 7;
        if (strncmp(p, "localhost/", 10) == 0) p += 9;
    } else if (strncmp(p, "file:", 5) == 0) {
        p += 5;
    }
    size_t k = 0;
    for (; *p && k + 1 < n; p++) {
        if (p[0] == '%' && p[1] && p[2]) {
            char hex[3] = {p[1], p[2], 0};
            char* end;
            long v = strtol(hex, &end, 16);
            if (*end == 0) {
                out[k++] = (char)v;
                p += 2;
                continue;
            }
        }
        out[k++] = *p;
    }
    out[k] = 0;
    while (k > 1 && out[k - 1] == '/') out[--k] = 0;
    return *p == 0;
}

static int resources_complete(const char* dir, char* why, size_t n)
{
    char path[4200], module[256] = {0};
    struct stat st;
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        snprintf(why, n, "the resources folder %s does not exist", dir);
        return 0;
    }
    snprintf(path, sizeof path, "%s/slavemodule.txt", dir);
    FILE* f = fopen(path, "r");
    if (!f) {
        snprintf(why, n, "the resources folder %s lacks slavemodule.txt", dir);
        return 0;
    }
    if (!fgets(module, sizeof module, f)) module[0] = 0;
    fclose(f);
    module[strcspn(module, "\r\n")] = 0;
    snprintf(path, sizeof path, "%s/%s.py", dir, module);
    if (!module[0] || stat(path, &st) != 0) {
        snprintf(why, n, "the resources folder %s lacks the slave module '%s.py'", dir, module);
        return 0;
    }
    return 1;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    const char* name = instanceName ? instanceName : "?";
    if (!functions || !instanceName || !instanceName[0]) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: an instance name and callback functions are required");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: this FMU supports co-simulation only (fmuType %d)",
                 (int)fmuType);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, GUARD_GUID) != 0) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: GUID %s does not match this FMU's %s (the "
                 "modelDescription.xml belongs to another FMU or version)", fmuGUID ? fmuGUID : "(null)", GUARD_GUID);
        return NULL;
    }
    char dir[4096], why[4400];
    if (!fmuResourceLocation || !decode_uri(fmuResourceLocation, dir, sizeof dir)) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: no usable resource location given");
        return NULL;
    }
    if (!resources_complete(dir, why, sizeof why)) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: %s (extract the whole FMU)", why);
        return NULL;
    }
    if (!load_inner()) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate: %s", lib_error);
        return NULL;
    }
    Guard* g = (Guard*)calloc(1, sizeof(Guard));
    if (!g) return NULL;
    g->magic = STATE_MAGIC;
    g->host = *functions;
    g->own = *functions;
    g->own.logger = guard_logger;
    g->own.componentEnvironment = g;
    g->name = strdup(name);
    g->host_logging = loggingOn ? 1 : 0;
    /* the decoded folder: PythonFMU itself only strips "file://" and decodes "%20" */
    g->inner = p_fmi2Instantiate(instanceName, fmuType, fmuGUID, dir, &g->own, visible, 1);
    if (!g->inner) {
        host_log(functions, name, fmi2Error, "fmi2Instantiate failed (the reason is logged above)");
        free(g->name);
        free(g);
        return NULL;
    }
    g->next = live;
    live = g;
    return g;
}

void fmi2FreeInstance(fmi2Component c)
{
    Guard* g = (Guard*)c;
    if (!g || !is_live(g) || g->magic != STATE_MAGIC) return; /* NULL, foreign or already freed: nothing */
    if (!g->dead) p_fmi2FreeInstance(g->inner);
    for (Guard** q = &live; *q; q = &(*q)->next) {
        if (*q == g) {
            *q = g->next;
            break;
        }
    }
    g->magic = 0;
    free(g->name);
    free(g);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    Guard* g = use(c, "fmi2SetDebugLogging");
    if (!g) return fmi2Error;
    (void)n;
    (void)categories;
    g->host_logging = loggingOn ? 1 : 0;
    return fmi2OK; /* PythonFMU keeps logging everything to this library, which filters */
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start, fmi2Boolean stopDef,
                               fmi2Real stop)
{
    Guard* g = use(c, "fmi2SetupExperiment");
    if (!g) return fmi2Error;
    if (!isfinite(start) || (stopDef && !(stop >= start)) || (tolDef && !(tol > 0))) {
        host_log(&g->host, g->name, fmi2Error, "fmi2SetupExperiment: invalid start %g / stop %g / tolerance %g",
                 start, stop, tol);
        return fmi2Error;
    }
    fmi2Status s = done(g, p_fmi2SetupExperiment(g->inner, tolDef, tol, start, stopDef, stop), fmi2Error);
    if (s <= fmi2Warning) {
        g->have_time = 1;
        g->time = start;
    }
    return s;
}

#define SIMPLE(call)                                          \
    fmi2Status call(fmi2Component c)                          \
    {                                                         \
        Guard* g = use(c, #call);                             \
        if (!g) return fmi2Error;                             \
        return done(g, p_##call(g->inner), fmi2Error);        \
    }
SIMPLE(fmi2EnterInitializationMode)
SIMPLE(fmi2ExitInitializationMode)
SIMPLE(fmi2Terminate)

fmi2Status fmi2Reset(fmi2Component c)
{
    Guard* g = use(c, "fmi2Reset");
    if (!g) return fmi2Error;
    g->have_time = 0;
    return done(g, p_fmi2Reset(g->inner), fmi2Error);
}

#define ACCESS(call, type)                                                                   \
    fmi2Status call(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, type value[]) \
    {                                                                                        \
        Guard* g = use(c, #call);                                                            \
        if (!g) return fmi2Error;                                                            \
        if (nvr == 0) return fmi2OK;                                                         \
        if (!vr || !value) {                                                                 \
            host_log(&g->host, g->name, fmi2Error, #call ": null array");                    \
            return fmi2Error;                                                                \
        }                                                                                    \
        return done(g, p_##call(g->inner, vr, nvr, value), fmi2Error);                       \
    }
ACCESS(fmi2GetReal, fmi2Real)
ACCESS(fmi2GetInteger, fmi2Integer)
ACCESS(fmi2GetBoolean, fmi2Boolean)
ACCESS(fmi2GetString, fmi2String)
ACCESS(fmi2SetReal, const fmi2Real)
ACCESS(fmi2SetInteger, const fmi2Integer)
ACCESS(fmi2SetBoolean, const fmi2Boolean)
ACCESS(fmi2SetString, const fmi2String)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior)
{
    Guard* g = use(c, "fmi2DoStep");
    if (!g) return fmi2Error;
    if (!isfinite(t)) {
        host_log(&g->host, g->name, fmi2Error, "fmi2DoStep: communication point %g is not finite", t);
        return fmi2Error;
    }
    if (g->have_time) {
        double tol = 1e-9 * (fabs(g->time) > 1.0 ? fabs(g->time) : 1.0) + 1e-12;
        if (t < g->time - tol) {
            host_log(&g->host, g->name, fmi2Error, "fmi2DoStep: time goes backwards (communication point %.17g s, "
                     "the last step ended at %.17g s); restore an FMU state to go back", t, g->time);
            return fmi2Error;
        }
    }
    fmi2Status s = done(g, p_fmi2DoStep(g->inner, t, h, noSetPrior), fmi2Discard);
    if (s == fmi2OK || s == fmi2Warning) {
        g->have_time = 1;
        g->time = t + h;
    }
    return s;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    Guard* g = use(c, "fmi2CancelStep");
    if (!g) return fmi2Error;
    host_log(&g->host, g->name, fmi2Error, "fmi2CancelStep: not supported (steps are synchronous)");
    return fmi2Error;
}

#define STATUS(call, type)                                                                  \
    fmi2Status call(fmi2Component c, const fmi2StatusKind s, type* value)                   \
    {                                                                                       \
        Guard* g = use(c, #call);                                                           \
        (void)s;                                                                            \
        (void)value;                                                                        \
        if (!g) return fmi2Error;                                                           \
        host_log(&g->host, g->name, fmi2Discard, #call ": not supported (steps are synchronous)"); \
        return fmi2Discard;                                                                 \
    }
STATUS(fmi2GetStatus, fmi2Status)
STATUS(fmi2GetRealStatus, fmi2Real)
STATUS(fmi2GetIntegerStatus, fmi2Integer)
STATUS(fmi2GetBooleanStatus, fmi2Boolean)
STATUS(fmi2GetStringStatus, fmi2String)

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[],
                                       const fmi2Real d[])
{
    Guard* g = use(c, "fmi2SetRealInputDerivatives");
    (void)vr, (void)n, (void)o, (void)d;
    if (!g) return fmi2Error;
    host_log(&g->host, g->name, fmi2Error, "fmi2SetRealInputDerivatives: not supported");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real d[])
{
    Guard* g = use(c, "fmi2GetRealOutputDerivatives");
    (void)vr, (void)n, (void)o, (void)d;
    if (!g) return fmi2Error;
    host_log(&g->host, g->name, fmi2Error, "fmi2GetRealOutputDerivatives: not supported");
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real du[], fmi2Real dz[])
{
    Guard* g = use(c, "fmi2GetDirectionalDerivative");
    (void)u, (void)nu, (void)z, (void)nz, (void)du, (void)dz;
    if (!g) return fmi2Error;
    host_log(&g->host, g->name, fmi2Error, "fmi2GetDirectionalDerivative: not supported");
    return fmi2Error;
}

/* -- FMU states ---------------------------------------------------------- */

static State* find_state(fmi2FMUstate s, State** prev)
{
    State* p = NULL;
    for (State* q = issued; q; p = q, q = q->next) {
        if ((void*)q == s) {
            if (prev) *prev = p;
            return q;
        }
    }
    return NULL;
}

static State* new_state(Guard* g, fmi2FMUstate inner)
{
    State* st = (State*)calloc(1, sizeof(State));
    if (!st) return NULL;
    st->magic = STATE_MAGIC;
    st->inner = inner;
    st->have_time = g->have_time;
    st->time = g->time;
    st->next = issued;
    issued = st;
    return st;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    Guard* g = use(c, "fmi2GetFMUstate");
    if (!g) return fmi2Error;
    if (!state) return fmi2Error;
    State* own = *state ? find_state(*state, NULL) : NULL;
    if (own) { /* overwrite a state of ours in place (FMI 2.0 allows passing an existing state) */
        fmi2FMUstate inner = NULL;
        fmi2Status s = done(g, p_fmi2GetFMUstate(g->inner, &inner), fmi2Error);
        if (s > fmi2Warning) return s;
        p_fmi2FreeFMUstate(g->inner, &own->inner);
        own->inner = inner;
        own->have_time = g->have_time;
        own->time = g->time;
        return s;
    }
    fmi2FMUstate inner = NULL;
    fmi2Status s = done(g, p_fmi2GetFMUstate(g->inner, &inner), fmi2Error);
    if (s > fmi2Warning) return s;
    State* st = new_state(g, inner);
    if (!st) return fmi2Error;
    *state = st;
    return s;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Guard* g = use(c, "fmi2SetFMUstate");
    if (!g) return fmi2Error;
    State* st = state ? find_state(state, NULL) : NULL;
    if (!st) {
        host_log(&g->host, g->name, fmi2Error, "fmi2SetFMUstate: the state was not made by this FMU "
                 "(another FMU's state, a freed state or a null pointer); the instance is unchanged");
        return fmi2Error;
    }
    fmi2Status s = done(g, p_fmi2SetFMUstate(g->inner, st->inner), fmi2Error);
    if (s <= fmi2Warning) {
        g->have_time = st->have_time;
        g->time = st->time;
    }
    return s;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    Guard* g = use(c, "fmi2FreeFMUstate");
    if (!g) return fmi2Error;
    if (!state || !*state) return fmi2OK;
    State* prev = NULL;
    State* st = find_state(*state, &prev);
    if (!st) {
        host_log(&g->host, g->name, fmi2Error, "fmi2FreeFMUstate: the state was not made by this FMU");
        return fmi2Error;
    }
    fmi2Status s = done(g, p_fmi2FreeFMUstate(g->inner, &st->inner), fmi2Error);
    if (prev) prev->next = st->next; else issued = st->next;
    st->magic = 0;
    free(st);
    *state = NULL;
    return s;
}

#define HEADER (sizeof(SER_MAGIC) - 1 + sizeof(GUARD_GUID) + sizeof(int) + sizeof(double))

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size)
{
    Guard* g = use(c, "fmi2SerializedFMUstateSize");
    if (!g) return fmi2Error;
    State* st = state ? find_state(state, NULL) : NULL;
    if (!st || !size) {
        host_log(&g->host, g->name, fmi2Error, "fmi2SerializedFMUstateSize: the state was not made by this FMU");
        return fmi2Error;
    }
    size_t n = 0;
    fmi2Status s = done(g, p_fmi2SerializedFMUstateSize(g->inner, st->inner, &n), fmi2Error);
    *size = n + HEADER;
    return s;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    Guard* g = use(c, "fmi2SerializeFMUstate");
    if (!g) return fmi2Error;
    State* st = state ? find_state(state, NULL) : NULL;
    size_t n = 0;
    if (!st || !bytes || p_fmi2SerializedFMUstateSize(g->inner, st->inner, &n) > fmi2Warning || size < n + HEADER) {
        host_log(&g->host, g->name, fmi2Error, "fmi2SerializeFMUstate: not a state of this FMU, or the buffer "
                 "is smaller than fmi2SerializedFMUstateSize");
        return fmi2Error;
    }
    char* p = bytes;
    memcpy(p, SER_MAGIC, sizeof(SER_MAGIC) - 1);
    p += sizeof(SER_MAGIC) - 1;
    memcpy(p, GUARD_GUID, sizeof(GUARD_GUID));
    p += sizeof(GUARD_GUID);
    memcpy(p, &st->have_time, sizeof(int));
    p += sizeof(int);
    memcpy(p, &st->time, sizeof(double));
    p += sizeof(double);
    return done(g, p_fmi2SerializeFMUstate(g->inner, st->inner, p, n), fmi2Error);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state)
{
    Guard* g = use(c, "fmi2DeSerializeFMUstate");
    if (!g) return fmi2Error;
    if (!bytes || !state || size <= HEADER || memcmp(bytes, SER_MAGIC, sizeof(SER_MAGIC) - 1) != 0 ||
        memcmp(bytes + sizeof(SER_MAGIC) - 1, GUARD_GUID, sizeof(GUARD_GUID)) != 0) {
        host_log(&g->host, g->name, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a serialized state of "
                 "this FMU (GUID %s)", GUARD_GUID);
        return fmi2Error;
    }
    const char* p = bytes + sizeof(SER_MAGIC) - 1 + sizeof(GUARD_GUID);
    int have_time;
    double time;
    memcpy(&have_time, p, sizeof(int));
    memcpy(&time, p + sizeof(int), sizeof(double));
    fmi2FMUstate inner = NULL;
    fmi2Status s = done(g, p_fmi2DeSerializeFMUstate(g->inner, bytes + HEADER, size - HEADER, &inner), fmi2Error);
    if (s > fmi2Warning) return s;
    State* st = new_state(g, inner);
    if (!st) return fmi2Error;
    st->have_time = have_time;
    st->time = time;
    *state = st;
    return s;
}
