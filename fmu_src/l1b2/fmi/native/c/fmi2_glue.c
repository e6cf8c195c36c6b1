/* fmi2_glue.c - the FMI 2.0 co-simulation API of the l1b2 native FMUs over fmu_core */
#include <stdlib.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

typedef struct {
    Instance core;
    fmi2CallbackFunctions cb;
} Fmi2Instance;

static void fmi2_log(Instance* c, int status, const char* category, const char* message)
{
    /* the message as the format, '%' doubled: hosts that print the format without formatting (fmpy)
     * and hosts that format it show the same text */
    Fmi2Instance* f = (Fmi2Instance*)c;
    char buf[4 * MSG_LEN];
    size_t k = 0;
    for (const char* p = message; *p && k + 2 < sizeof buf; p++) {
        if (*p == '%') buf[k++] = '%';
        buf[k++] = *p;
    }
    buf[k] = '\0';
    if (f->cb.logger) f->cb.logger(f->cb.componentEnvironment, c->name, (fmi2Status)status, category, buf);
}

#define INST ((Instance*)c)

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    (void)n; (void)categories;
    INST->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation; (void)visible;
    Fmi2Instance* f = (Fmi2Instance*)core_new(sizeof(Fmi2Instance), instanceName, loggingOn);
    if (!f) return NULL;
    if (functions) f->cb = *functions;
    f->core.log = fmi2_log;
    if (fmuType != fmi2CoSimulation) {
        core_log(&f->core, ST_ERROR, "%s: fmi2Instantiate: only co-simulation is supported", MODEL_IDENTIFIER);
        free(f);
        return NULL;
    }
    if (core_check_token(&f->core, "fmi2Instantiate", "GUID", fmuGUID)) {
        free(f);
        return NULL;
    }
    return (fmi2Component)f;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    core_start_time(INST, startTime);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return (fmi2Status)core_enter_initialization(INST); }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return (fmi2Status)core_exit_initialization(INST); }

fmi2Status fmi2Terminate(fmi2Component c)
{
    core_terminate(INST);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    core_reset(INST);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[])
{
    return (fmi2Status)core_get_real(INST, vr, n, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[])
{
    return (fmi2Status)core_set_real(INST, vr, n, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[])
{
    return (fmi2Status)core_get_boolean(INST, vr, n, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[])
{
    return (fmi2Status)core_set_boolean(INST, vr, n, value);
}

static fmi2Status no_such_type(fmi2Component c, const char* call, size_t n, const fmi2ValueReference vr[])
{
    if (n == 0) return fmi2OK;
    core_log(INST, ST_ERROR, "%s: value reference %u is not a variable of this type (%s has only Real and "
             "Boolean variables)", call, vr[0], MODEL_IDENTIFIER);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[])
{
    (void)value;
    return no_such_type(c, "fmi2GetInteger", n, vr);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[])
{
    (void)value;
    return no_such_type(c, "fmi2SetInteger", n, vr);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[])
{
    (void)value;
    return no_such_type(c, "fmi2GetString", n, vr);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[])
{
    (void)value;
    return no_such_type(c, "fmi2SetString", n, vr);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    void* s = core_state_get(INST, *state);
    if (!s) return fmi2Error;
    *state = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    return (fmi2Status)core_set_state(INST, (const Snapshot*)state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    (void)c;
    core_state_free(state);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size)
{
    (void)c; (void)state;
    *size = core_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    return (fmi2Status)core_state_serialize(INST, "fmi2SerializeFMUstate", state, bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state)
{
    void* s = core_state_deserialize(INST, bytes, size, *state);
    if (!s) return fmi2Error;
    *state = s;
    return fmi2OK;
}

static fmi2Status unsupported(fmi2Component c, const char* call)
{
    return (fmi2Status)core_unsupported(INST, call, "");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)n; (void)order; (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)n; (void)order; (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    return (fmi2Status)core_do_step(INST, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value)
{
    (void)s; (void)value;
    return unsupported(c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value)
{
    if (s == fmi2LastSuccessfulTime) {
        *value = INST->time;
        return fmi2OK;
    }
    return unsupported(c, "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value)
{
    (void)s; (void)value;
    return unsupported(c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value)
{
    (void)s; (void)value;
    return unsupported(c, "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value)
{
    (void)s; (void)value;
    return unsupported(c, "fmi2GetStringStatus");
}
