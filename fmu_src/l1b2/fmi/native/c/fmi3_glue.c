/* fmi3_glue.c - the FMI 3.0 co-simulation API of the l1b2 native FMUs over fmu_core
 * (the calls of other interfaces and types are in fmi3_stubs.c: they return fmi3Error) */
#include <stdlib.h>

#include "fmi3Functions.h"
#include "fmu_core.h"

typedef struct {
    Instance core;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
} Fmi3Instance;

static void fmi3_log(Instance* c, int status, const char* category, const char* message)
{
    Fmi3Instance* f = (Fmi3Instance*)c;
    if (f->logMessage) f->logMessage(f->env, (fmi3Status)status, category, message);
}

#define INST ((Instance*)instance)

void l1b2_fmi3_log(fmi3Instance instance, const char* call)
{
    core_unsupported(INST, call, " (co-simulation, Float64 and Boolean variables only)");
}

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t n, const fmi3String categories[])
{
    (void)n; (void)categories;
    INST->logging_on = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    Fmi3Instance* f = (Fmi3Instance*)core_new(sizeof(Fmi3Instance), instanceName, loggingOn);
    if (!f) return NULL;
    f->env = instanceEnvironment;
    f->logMessage = logMessage;
    f->core.log = fmi3_log;
    if (core_check_token(&f->core, "fmi3InstantiateCoSimulation", "instantiation token", instantiationToken)) {
        free(f);
        return NULL;
    }
    if (eventModeUsed) {
        core_log(&f->core, ST_ERROR, "%s: fmi3InstantiateCoSimulation: event mode is not supported",
                 MODEL_IDENTIFIER);
        free(f);
        return NULL;
    }
    return (fmi3Instance)f;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (INST->mode == MODE_INSTANTIATED) core_start_time(INST, startTime);
    return (fmi3Status)core_enter_initialization(INST);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    return (fmi3Status)core_exit_initialization(INST);
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    core_terminate(INST);
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    core_reset(INST);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    if (nValues != nvr) {
        core_log(INST, ST_ERROR, "fmi3GetFloat64: %zu values for %zu value references (scalars only)", nValues, nvr);
        return fmi3Error;
    }
    return (fmi3Status)core_get_real(INST, vr, nvr, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    if (nValues != nvr) {
        core_log(INST, ST_ERROR, "fmi3SetFloat64: %zu values for %zu value references (scalars only)", nValues, nvr);
        return fmi3Error;
    }
    return (fmi3Status)core_set_real(INST, vr, nvr, values);
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues)
{
    int v[64];
    if (nValues != nvr) return fmi3Error;
    for (size_t i = 0; i < nvr; i += 64) {
        size_t k = nvr - i < 64 ? nvr - i : 64;
        if (core_get_boolean(INST, vr + i, k, v) != ST_OK) return fmi3Error;
        for (size_t j = 0; j < k; j++) values[i + j] = v[j] ? fmi3True : fmi3False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues)
{
    int v[64];
    if (nValues != nvr) return fmi3Error;
    for (size_t i = 0; i < nvr; i += 64) {
        size_t k = nvr - i < 64 ? nvr - i : 64;
        for (size_t j = 0; j < k; j++) v[j] = values[i + j] ? 1 : 0;
        if (core_set_boolean(INST, vr + i, k, v) != ST_OK) return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState* state)
{
    void* s = core_state_get(INST, *state);
    if (!s) return fmi3Error;
    *state = s;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    return (fmi3Status)core_set_state(INST, (const Snapshot*)state);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState* state)
{
    (void)instance;
    core_state_free(state);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t* size)
{
    (void)instance; (void)state;
    *size = core_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte serializedState[], size_t size)
{
    return (fmi3Status)core_state_serialize(INST, "fmi3SerializeFMUState", state, (char*)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState* state)
{
    void* s = core_state_deserialize(INST, (const char*)serializedState, size, *state);
    if (!s) return fmi3Error;
    *state = s;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    (void)instance;
    return fmi3OK; /* without event mode the instance is in step mode after initialisation */
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn,
                      fmi3Float64* lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    int status = core_do_step(INST, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime)
        *lastSuccessfulTime = status == ST_OK ? currentCommunicationPoint + communicationStepSize
                                              : currentCommunicationPoint;
    return (fmi3Status)status;
}
