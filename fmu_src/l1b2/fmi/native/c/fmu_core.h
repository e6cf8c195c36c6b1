/*
 * fmu_core.h - the FMI-version-independent part of the l1b2 native FMUs.
 *
 * Every variable of the FMU is one double in Instance.r, indexed by its value
 * reference (Booleans hold 0 or 1), exactly the variables, value references and
 * start values of the Python FMU of the same name (model_data.h is generated
 * from its modelDescription.xml by l1b2.fmi.native.build).
 *
 * The model (predictor_model.c, motor_model.c) provides ModelState (plain
 * doubles, part of the FMU state) and the hooks declared below. The glue
 * (fmi2_glue.c, fmi3_glue.c) maps the FMI calls onto the core functions.
 *
 * Status rules (the Python FMUs' rules, l1b2.fmi.adapter):
 *  - unknown value reference, wrong type: the call returns Error, one log line;
 *  - setting an output, a fixed parameter after initialisation, or a parameter to a value that is not
 *    finite or outside its declared range: the whole call is refused (Error, nothing set);
 *  - a communication step above MAX_STEP_S: Discard with a log line, the instance stays usable;
 *  - a call in the wrong mode: no effect, one log line with status Error; DoStep
 *    returns Discard, the other calls OK;
 *  - a non-finite or out-of-range input, an invalid step, a failed model step:
 *    DoStep returns Discard with the reason in the log, and the instance refuses
 *    further steps (Discard) until an FMU state taken before the error is restored
 *    or the instance is reset;
 *  - a failed initialisation is logged (Error) and makes every DoStep Discard.
 */
#ifndef L1B2_FMU_CORE_H
#define L1B2_FMU_CORE_H

#include <stddef.h>

#include "model_data.h"
#include "model.h"

enum { ST_OK = 0, ST_WARNING = 1, ST_DISCARD = 2, ST_ERROR = 3, ST_FATAL = 4 };
enum { MODE_INSTANTIATED = 0, MODE_INITIALIZATION = 1, MODE_STEPPING = 2, MODE_TERMINATED = 3 };

#define MSG_LEN 600

/* what an FMU state holds: every variable, the error flag and the model's own state */
typedef struct {
    unsigned long long tag;      /* STATE_TAG of the FMU that took it (a state of another FMU is refused) */
    double r[NV];
    int failed;
    char failmsg[MSG_LEN];
    ModelState ms;
} Snapshot;

typedef struct Instance {
    Snapshot s;                  /* the state proper */
    int mode;
    int outputs_stale;           /* initialization mode: outputs to compute before they are read */
    int logging_on;
    double time;                 /* the current communication point */
    char name[128];
    void (*log)(struct Instance*, int status, const char* category, const char* message);
    void* env;                   /* the glue's callbacks */
    void* env2;
} Instance;

/* the model's hooks (msg: MSG_LEN bytes for the reason of a failure) */
int model_initialize(Instance* c, char* msg);            /* 0: done; else the reason in msg */
int model_do_step(Instance* c, double t, double h, char* msg);
void model_refresh(Instance* c);                         /* outputs from the restored state */
void model_set_start_time(Instance* c, double t0);

/* core */
void core_init(Instance* c, const char* name);
void core_reset(Instance* c);
void core_log(Instance* c, int status, const char* fmt, ...);
int core_refused(Instance* c, const char* call, int allowed_mask);
int core_get_real(Instance* c, const unsigned* vr, size_t n, double* value);
int core_set_real(Instance* c, const unsigned* vr, size_t n, const double* value);
int core_get_boolean(Instance* c, const unsigned* vr, size_t n, int* value);
int core_set_boolean(Instance* c, const unsigned* vr, size_t n, const int* value);
int core_enter_initialization(Instance* c);
int core_exit_initialization(Instance* c);
int core_do_step(Instance* c, double t, double h);
int core_check_inputs(Instance* c, char* msg);
void core_after_restore(Instance* c);
int core_get_state(Instance* c, Snapshot* out);
int core_set_state(Instance* c, const Snapshot* s);
int core_deserialize(Instance* c, const char* bytes, size_t size, Snapshot* out);
size_t core_serialized_size(void);
void core_serialize(const Snapshot* s, char* bytes);

/* shared by the FMI 2.0 and FMI 3.0 glue: instances (size: the glue's struct, Instance first), start time,
 * refusals, FMU states (a state is a Snapshot; NULL from get/deserialize: out of memory or refused) */
Instance* core_new(size_t size, const char* name, int logging_on);
int core_check_token(Instance* c, const char* call, const char* what, const char* token); /* 0: this FMU's */
void core_start_time(Instance* c, double t0);
void core_terminate(Instance* c);
int core_unsupported(Instance* c, const char* call, const char* what);  /* logs, returns ST_ERROR */
void* core_state_get(Instance* c, void* state);                         /* into state, or a new one */
void core_state_free(void** state);
int core_state_serialize(Instance* c, const char* call, const void* state, char* bytes, size_t size);
void* core_state_deserialize(Instance* c, const char* bytes, size_t size, void* state);

#define MASK(m) (1 << (m))

#endif
