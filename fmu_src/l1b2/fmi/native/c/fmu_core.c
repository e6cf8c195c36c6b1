/* fmu_core.c - variables, modes, steps and FMU state of the l1b2 native FMUs (see fmu_core.h) */
#include "fmu_core.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char* const MODE_NAME[] = {"instantiated", "initialization mode", "stepping", "terminated"};
static const char* const MODE_WHEN[] = {"before initialisation", "in initialization mode",
                                        "after initialisation", "after Terminate"};
static const char* const MODE_HINT[] = {
    "call EnterInitializationMode and ExitInitializationMode first",
    "call ExitInitializationMode first",
    "the instance is already initialised",
    "call Reset or instantiate the FMU again"};

void core_log(Instance* c, int status, const char* fmt, ...)
{
    char buf[2 * MSG_LEN];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (!c->log) return;
    if (status == ST_OK && !c->logging_on) return;
    const char* cat = status == ST_ERROR ? "logStatusError" : status == ST_DISCARD ? "logStatusDiscard"
                    : status == ST_WARNING ? "logStatusWarning" : status == ST_FATAL ? "logStatusFatal" : "logAll";
    c->log(c, status, cat, buf);
}

void core_init(Instance* c, const char* name)
{
    memset(c, 0, sizeof *c);
    snprintf(c->name, sizeof c->name, "%s", name ? name : MODEL_IDENTIFIER);
    core_reset(c);
}

void core_reset(Instance* c)
{
    for (int i = 0; i < NV; i++) c->s.r[i] = VAR_START[i];
    c->s.failed = 0;
    c->s.failmsg[0] = '\0';
    memset(&c->s.ms, 0, sizeof c->s.ms);
    c->mode = MODE_INSTANTIATED;
    c->outputs_stale = 1;
    c->time = 0.0;
}

static void fail(Instance* c, const char* msg)
{
    c->s.failed = 1;
    snprintf(c->s.failmsg, MSG_LEN, "%.*s", MSG_LEN - 1, msg); /* a long reason is cut */
    core_log(c, ST_ERROR, "%s", msg);
}

int core_refused(Instance* c, const char* call, int allowed_mask)
{
    if (allowed_mask & MASK(c->mode)) return 0;
    char allowed[160] = "";
    for (int m = 0; m < 4; m++) {
        if (!(allowed_mask & MASK(m))) continue;
        size_t k = strlen(allowed);
        snprintf(allowed + k, sizeof allowed - k, "%s'%s'", k ? " or " : "", MODE_NAME[m]);
    }
    core_log(c, ST_ERROR, "%s: %s called %s (mode '%s', FMI allows it only in %s): %s; the call has no effect",
             MODEL_IDENTIFIER, call, MODE_WHEN[c->mode], MODE_NAME[c->mode], allowed, MODE_HINT[c->mode]);
    return 1;
}

static int bad_reference(Instance* c, unsigned vr, int want_type, const char* what)
{
    if (vr >= NV) {
        core_log(c, ST_ERROR, "%s: value reference %u is not a variable of %s (it has %d, 0-%d)", what, vr,
                 MODEL_IDENTIFIER, NV, NV - 1);
        return 1;
    }
    if (VAR_TYPE[vr] != want_type) {
        core_log(c, ST_ERROR, "%s: value reference %u (%s) is not a %s variable", what, vr, VAR_NAME[vr],
                 want_type == VT_REAL ? "Real" : "Boolean");
        return 1;
    }
    return 0;
}

static void outputs_for_initialization(Instance* c)
{
    if (c->mode == MODE_INITIALIZATION && c->outputs_stale) {
        char msg[MSG_LEN];
        c->outputs_stale = 0;
        (void)model_initialize(c, msg); /* inputs may be provisional here; checked at exit */
    }
}

int core_get_real(Instance* c, const unsigned* vr, size_t n, double* value)
{
    for (size_t i = 0; i < n; i++) {
#ifdef VR_TIME
        if (vr[i] == VR_TIME) {
            value[i] = c->time;
            continue;
        }
#endif
        if (bad_reference(c, vr[i], VT_REAL, "GetReal")) return ST_ERROR;
        if (VAR_CAUS[vr[i]] == VC_OUTPUT) outputs_for_initialization(c);
        value[i] = c->s.r[vr[i]];
    }
    return ST_OK;
}

/* why a Set call must be refused as a whole (nothing set), as the Python FMUs refuse it: an output, a fixed
 * parameter after initialisation, a parameter value that is not finite or outside its declared range */
static int set_refused(Instance* c, const unsigned* vr, size_t n, const double* value, int type, const char* call)
{
    for (size_t i = 0; i < n; i++) {
        if (bad_reference(c, vr[i], type, call)) return 1;
        const unsigned k = vr[i];
        if (VAR_CAUS[k] == VC_OUTPUT) {
            core_log(c, ST_ERROR, "%s: %s: %s is an output, computed by the FMU: it cannot be set; nothing done",
                     MODEL_IDENTIFIER, call, VAR_NAME[k]);
            return 1;
        }
        if (VAR_CAUS[k] != VC_PARAMETER) continue;
        if (VAR_FIXED[k] && (c->mode == MODE_STEPPING || c->mode == MODE_TERMINATED)) {
            core_log(c, ST_ERROR, "%s: %s: %s is a fixed parameter: it can only be set before "
                     "ExitInitializationMode (Reset to change it); nothing done", MODEL_IDENTIFIER, call, VAR_NAME[k]);
            return 1;
        }
        if (type == VT_REAL && !(isfinite(value[i]) && VAR_MIN[k] <= value[i] && value[i] <= VAR_MAX[k])) {
            core_log(c, ST_ERROR, "%s: %s: parameter %s [%s] = %.17g is %s; the value is unchanged", MODEL_IDENTIFIER,
                     call, VAR_NAME[k], VAR_UNIT[k][0] ? VAR_UNIT[k] : "1", value[i],
                     isfinite(value[i]) ? "outside its declared range" : "not finite");
            return 1;
        }
    }
    return 0;
}

int core_set_real(Instance* c, const unsigned* vr, size_t n, const double* value)
{
    if (set_refused(c, vr, n, value, VT_REAL, "SetReal")) return ST_ERROR;
    for (size_t i = 0; i < n; i++) c->s.r[vr[i]] = value[i];
    c->outputs_stale = 1;
    return ST_OK;
}

int core_get_boolean(Instance* c, const unsigned* vr, size_t n, int* value)
{
    for (size_t i = 0; i < n; i++) {
        if (bad_reference(c, vr[i], VT_BOOLEAN, "GetBoolean")) return ST_ERROR;
        value[i] = c->s.r[vr[i]] != 0.0;
    }
    return ST_OK;
}

int core_set_boolean(Instance* c, const unsigned* vr, size_t n, const int* value)
{
    for (size_t i = 0; i < n; i++) {
        double x = value[i] ? 1.0 : 0.0;
        if (set_refused(c, vr + i, 1, &x, VT_BOOLEAN, "SetBoolean")) return ST_ERROR;
    }
    for (size_t i = 0; i < n; i++) c->s.r[vr[i]] = value[i] ? 1.0 : 0.0;
    c->outputs_stale = 1;
    return ST_OK;
}

int core_check_inputs(Instance* c, char* msg)
{
    for (int k = 0; k < N_INPUTS; k++) {
        int vr = INPUT_VR[k];
        double x = c->s.r[vr];
        if (!isfinite(x)) {
            snprintf(msg, MSG_LEN, "%s: input %s [%s] = %s is not finite", BLOCK_NAME, VAR_NAME[vr], VAR_UNIT[vr],
                     isnan(x) ? "nan" : (x > 0 ? "inf" : "-inf"));
            return 1;
        }
        if (x < INPUT_MIN[k]) {
            snprintf(msg, MSG_LEN, "%s: input %s [%s] = %.17g is below %.17g", BLOCK_NAME, VAR_NAME[vr],
                     VAR_UNIT[vr], x, INPUT_MIN[k]);
            return 1;
        }
        if (x > INPUT_MAX[k]) {
            snprintf(msg, MSG_LEN, "%s: input %s [%s] = %.17g is above %.17g", BLOCK_NAME, VAR_NAME[vr],
                     VAR_UNIT[vr], x, INPUT_MAX[k]);
            return 1;
        }
    }
#ifdef VR_direction
    if (fabs(fabs(c->s.r[VR_direction]) - 1.0) > 1e-9) {
        snprintf(msg, MSG_LEN, "%s: input direction [1] = %.17g must be +1 or -1", BLOCK_NAME, c->s.r[VR_direction]);
        return 1;
    }
#endif
    return 0;
}

int core_enter_initialization(Instance* c)
{
    if (core_refused(c, "EnterInitializationMode", MASK(MODE_INSTANTIATED))) return ST_OK;
    c->mode = MODE_INITIALIZATION;
    c->outputs_stale = 1;
    return ST_OK;
}

int core_exit_initialization(Instance* c)
{
    if (core_refused(c, "ExitInitializationMode", MASK(MODE_INITIALIZATION))) return ST_OK;
    c->mode = MODE_STEPPING;
    char msg[MSG_LEN], line[2 * MSG_LEN];
    if (model_initialize(c, msg)) {
        snprintf(line, sizeof line, "%s: initialisation failed: %s", MODEL_IDENTIFIER, msg);
        fail(c, line);
    }
    return ST_OK;
}

int core_do_step(Instance* c, double t, double h)
{
    char msg[MSG_LEN], line[2 * MSG_LEN];
    if (core_refused(c, "DoStep", MASK(MODE_STEPPING))) return ST_DISCARD;
    if (c->s.failed) {
        core_log(c, ST_ERROR, "%s: refusing to step after an error: %s (restore an FMU state taken before the "
                 "error with SetFMUState, or Reset)", MODEL_IDENTIFIER, c->s.failmsg);
        return ST_DISCARD;
    }
    if (!(isfinite(h) && h > 0)) {
        snprintf(line, sizeof line, "%s: invalid communication step %.17g s at t=%.17g", MODEL_IDENTIFIER, h, t);
        fail(c, line);
        return ST_DISCARD;
    }
    if (h > MAX_STEP_S) { /* not an error of the instance: a smaller step is accepted */
        core_log(c, ST_ERROR, "%s: communication step %.17g s at t=%.17g s is above this FMU's maximum %.17g s; step "
                 "refused, take smaller steps", MODEL_IDENTIFIER, h, t, MAX_STEP_S);
        return ST_DISCARD;
    }
    if (model_do_step(c, t, h, msg)) {
        snprintf(line, sizeof line, "%s: step at t=%.17g s failed: %s", MODEL_IDENTIFIER, t, msg);
        fail(c, line);
        return ST_DISCARD;
    }
    c->time = t + h;
    return ST_OK;
}

int core_get_state(Instance* c, Snapshot* out)
{
    c->s.tag = STATE_TAG;
    *out = c->s;
    return ST_OK;
}

int core_set_state(Instance* c, const Snapshot* s)
{
    if (!s || s->tag != STATE_TAG) {
        core_log(c, ST_ERROR, "%s: SetFMUState: the state is not one of this FMU; the instance is unchanged",
                 MODEL_IDENTIFIER);
        return ST_ERROR;
    }
    c->s = *s;
    core_after_restore(c);
    return ST_OK;
}

void core_after_restore(Instance* c)
{
    c->outputs_stale = 1;
    if (c->mode == MODE_STEPPING) model_refresh(c);
}

/* serialised state: magic, size of the snapshot, the snapshot's bytes */
#define STATE_MAGIC 0x4C314232u /* "L1B2" */

size_t core_serialized_size(void) { return 2 * sizeof(unsigned) + sizeof(Snapshot); }

void core_serialize(const Snapshot* s, char* bytes)
{
    unsigned head[2] = {STATE_MAGIC, (unsigned)sizeof(Snapshot)};
    memcpy(bytes, head, sizeof head);
    memcpy(bytes + sizeof head, s, sizeof *s);
}

int core_deserialize(Instance* c, const char* bytes, size_t size, Snapshot* out)
{
    unsigned head[2];
    if (size != core_serialized_size()) {
        core_log(c, ST_ERROR, "DeserializeFMUState: %zu bytes given, a state of %s has %zu", size,
                 MODEL_IDENTIFIER, core_serialized_size());
        return ST_ERROR;
    }
    memcpy(head, bytes, sizeof head);
    if (head[0] != STATE_MAGIC || head[1] != sizeof(Snapshot)
        || ((const Snapshot*)(const void*)(bytes + sizeof head))->tag != STATE_TAG) {
        core_log(c, ST_ERROR, "DeserializeFMUState: not a serialised state of this %s FMU", MODEL_IDENTIFIER);
        return ST_ERROR;
    }
    memcpy(out, bytes + sizeof head, sizeof *out);
    return ST_OK;
}

/* ---- instance and FMU state handling shared by the FMI 2.0 and FMI 3.0 glue ---- */

Instance* core_new(size_t size, const char* name, int logging_on)
{
    Instance* c = (Instance*)calloc(1, size);
    if (!c) return NULL;
    core_init(c, name);
    c->logging_on = logging_on;
    return c;
}

int core_check_token(Instance* c, const char* call, const char* what, const char* token)
{
    if (token && strcmp(token, INSTANTIATION_TOKEN) == 0) return 0;
    core_log(c, ST_ERROR, "%s: %s: %s %s does not match this FMU's %s", MODEL_IDENTIFIER, call, what,
             token ? token : "(null)", INSTANTIATION_TOKEN);
    return 1;
}

void core_start_time(Instance* c, double t0)
{
    c->time = t0;
    model_set_start_time(c, t0);
}

void core_terminate(Instance* c) { c->mode = MODE_TERMINATED; }

int core_unsupported(Instance* c, const char* call, const char* what)
{
    core_log(c, ST_ERROR, "%s: %s is not supported%s", MODEL_IDENTIFIER, call, what);
    return ST_ERROR;
}

void* core_state_get(Instance* c, void* state)
{
    Snapshot* s = state ? (Snapshot*)state : (Snapshot*)malloc(sizeof(Snapshot));
    if (s) core_get_state(c, s);
    return s;
}

void core_state_free(void** state)
{
    if (state) {
        free(*state);
        *state = NULL;
    }
}

int core_state_serialize(Instance* c, const char* call, const void* state, char* bytes, size_t size)
{
    if (!state || size < core_serialized_size()) {
        core_log(c, ST_ERROR, "%s: buffer of %zu bytes, %zu needed", call, size, core_serialized_size());
        return ST_ERROR;
    }
    core_serialize((const Snapshot*)state, bytes);
    return ST_OK;
}

void* core_state_deserialize(Instance* c, const char* bytes, size_t size, void* state)
{
    Snapshot tmp;
    if (core_deserialize(c, bytes, size, &tmp) != ST_OK) return NULL;
    Snapshot* s = state ? (Snapshot*)state : (Snapshot*)malloc(sizeof(Snapshot));
    if (s) *s = tmp;
    return s;
}
