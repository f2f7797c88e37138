/*
 * mpc_native_fmi3.c -- the mpc_actuator model as a native FMI 3.0 co-simulation FMU, no Python needed.
 *
 * The same model as the FMI 2.0 native FMU: this file includes mpc_native.c (the integrator, the force-kernel
 * table, the checks, the FMU state) and the generated headers (mpc_native_gen.h: the equations traced from
 * fmu_src; mpc_native_vars.h: here generated from the FMI 3.0 modelDescription, so the value references are
 * FMI 3.0's). mpc_native.c's FMI 2.0 functions are compiled as static functions (EXPORT is defined as static
 * before the include) and each FMI 3.0 function below calls its FMI 2.0 counterpart: the same checks, error
 * messages (they name the FMI 2.0 call), communication-point rules and numbers. Only the FMI 3.0 calls are
 * exported. Declarations: the FMI 3.0 standard headers (fmi3Functions.h, shipped in sources/).
 *
 * Not supported (fmi3Error, logged): model exchange and scheduled execution, event mode, early return, clocks,
 * arrays, intermediate update, directional/adjoint derivatives, output derivatives.
 *
 * Build: cc -std=c99 -O2 -shared -fPIC -fvisibility=hidden -ffp-contract=off -o mpc_actuator_native_fmi3.so
 *   mpc_native_fmi3.c -lm
 */
#if defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wunused-function" /* mpc_native.c's FMI 2.0 functions not called here */
#endif
#define EXPORT static
#include "mpc_native.c"
#undef EXPORT

#include "fmi3Functions.h"

/* the FMI 3.0 logger behind mpc_native.c's (FMI 2.0) logger: fmi2Instance's componentEnvironment is this link */
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Link3;

static void log_to_fmi3(fmi2ComponentEnvironment env, fmi2String name, fmi2Status st, fmi2String category,
                        fmi2String fmt, ...) {
    (void)name;
    Link3 *link = (Link3 *)env;
    if (!link || !link->log) return;
    char msg[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    link->log(link->env, (fmi3Status)st, category, msg); /* fmi2Status and fmi3Status: the same values */
}

static fmi3Status st3(fmi2Status s) { return s == fmi2Pending ? fmi3Error : (fmi3Status)s; }

static fmi3Status unsupported(fmi3Instance instance, const char *what) {
    if (instance) ERROR((Instance *)instance, "%s: not supported by this FMU", what);
    return fmi3Error;
}

/* value-reference ranges: no array variables, so nValues must equal nValueReferences */
static int sizes_ok(fmi3Instance instance, size_t nvr, size_t nvalues, const char *call) {
    if (nvr == nvalues) return 1;
    ERROR((Instance *)instance, "%s: %zu values for %zu value references (the model has no array variables)", call,
          nvalues, nvr);
    return 0;
}

/* ---- inquire version, logging ---- */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    return st3(fmi2SetDebugLogging(instance, loggingOn ? fmi2True : fmi2False, nCategories, categories));
}

/* ---- instantiation ---- */
fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    Link3 *link = (Link3 *)calloc(1, sizeof(Link3));
    if (!link) return NULL;
    link->env = instanceEnvironment;
    link->log = logMessage;
    fmi2CallbackFunctions cb = {log_to_fmi3, NULL, NULL, NULL, link};
    if (!instanceName) instanceName = "";
    if (eventModeUsed || nRequiredIntermediateVariables) { /* hasEventMode and intermediate update: false */
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       eventModeUsed ? "fmi3InstantiateCoSimulation: event mode is not supported (hasEventMode false)"
                                     : "fmi3InstantiateCoSimulation: no intermediate variables are provided");
        free(link);
        return NULL;
    }
    Instance *c = (Instance *)fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken, resourcePath, &cb,
                                              visible ? fmi2True : fmi2False, loggingOn ? fmi2True : fmi2False);
    if (!c) free(link);
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: this FMU is for co-simulation only (the FMI 2.0 native FMU has "
                   "model exchange)");
    (void)instanceName;
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU is for co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (!instance) return;
    free(((Instance *)instance)->cb.componentEnvironment);
    fmi2FreeInstance(instance);
}

/* ---- initialization, termination, reset ---- */
fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    fmi2Status s = fmi2SetupExperiment(instance, toleranceDefined ? fmi2True : fmi2False, tolerance, startTime,
                                       stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s != fmi2OK) return st3(s);
    return st3(fmi2EnterInitializationMode(instance));
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { return st3(fmi2ExitInitializationMode(instance)); }
fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return unsupported(instance, "fmi3EnterEventMode"); }
fmi3Status fmi3Terminate(fmi3Instance instance) { return st3(fmi2Terminate(instance)); }
fmi3Status fmi3Reset(fmi3Instance instance) { return st3(fmi2Reset(instance)); }

/* ---- variables: Float64 (time, V, outputs, parameters) and Boolean (contact, blocked) ---- */
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    if (!instance || (nvr && (!vr || !values))) return fmi3Error;
    if (!sizes_ok(instance, nvr, nValues, "fmi3GetFloat64")) return fmi3Error;
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] == VR_TIME) {
            values[k] = ((Instance *)instance)->m.t;
            continue;
        }
        fmi2Status s = fmi2GetReal(instance, &vr[k], 1, &values[k]);
        if (s != fmi2OK) return st3(s);
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    if (!instance || (nvr && (!vr || !values))) return fmi3Error;
    if (!sizes_ok(instance, nvr, nValues, "fmi3SetFloat64")) return fmi3Error;
    return st3(fmi2SetReal(instance, vr, nvr, values)); /* all or nothing, as fmi2SetReal */
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    if (!instance || (nvr && (!vr || !values))) return fmi3Error;
    if (!sizes_ok(instance, nvr, nValues, "fmi3GetBoolean")) return fmi3Error;
    for (size_t k = 0; k < nvr; k++) {
        fmi2Boolean b = fmi2False;
        fmi2Status s = fmi2GetBoolean(instance, &vr[k], 1, &b);
        if (s != fmi2OK) return st3(s);
        values[k] = b != fmi2False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    if (!instance || (nvr && (!vr || !values))) return fmi3Error;
    if (!sizes_ok(instance, nvr, nValues, "fmi3SetBoolean")) return fmi3Error;
    fmi2Boolean b[64];
    for (size_t k0 = 0; k0 < nvr; k0 += 64) { /* check all first (nothing set on an error), then set */
        size_t n = nvr - k0 < 64 ? nvr - k0 : 64;
        for (size_t k = 0; k < n; k++) b[k] = values[k0 + k] ? fmi2True : fmi2False;
        Instance probe = *(Instance *)instance;
        fmi2Status s = fmi2SetBoolean(&probe, &vr[k0], n, b);
        if (s != fmi2OK) return st3(s);
    }
    for (size_t k0 = 0; k0 < nvr; k0 += 64) {
        size_t n = nvr - k0 < 64 ? nvr - k0 : 64;
        for (size_t k = 0; k < n; k++) b[k] = values[k0 + k] ? fmi2True : fmi2False;
        fmi2SetBoolean(instance, &vr[k0], n, b);
    }
    return fmi3OK;
}

/* the model has no variables of the other types: zero value references is fine, any other is an error */
#define NO_VARIABLES(NAME, TYPE, CONST)                                                                        \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, CONST TYPE values[],     \
                    size_t nValues) {                                                                          \
        (void)vr; (void)values; (void)nValues;                                                                 \
        return st3(no_variables(instance, nvr, #NAME));                                                        \
    }
NO_VARIABLES(fmi3GetFloat32, fmi3Float32, )
NO_VARIABLES(fmi3GetInt8, fmi3Int8, )
NO_VARIABLES(fmi3GetUInt8, fmi3UInt8, )
NO_VARIABLES(fmi3GetInt16, fmi3Int16, )
NO_VARIABLES(fmi3GetUInt16, fmi3UInt16, )
NO_VARIABLES(fmi3GetInt32, fmi3Int32, )
NO_VARIABLES(fmi3GetUInt32, fmi3UInt32, )
NO_VARIABLES(fmi3GetInt64, fmi3Int64, )
NO_VARIABLES(fmi3GetUInt64, fmi3UInt64, )
NO_VARIABLES(fmi3GetString, fmi3String, )
NO_VARIABLES(fmi3SetFloat32, fmi3Float32, const)
NO_VARIABLES(fmi3SetInt8, fmi3Int8, const)
NO_VARIABLES(fmi3SetUInt8, fmi3UInt8, const)
NO_VARIABLES(fmi3SetInt16, fmi3Int16, const)
NO_VARIABLES(fmi3SetUInt16, fmi3UInt16, const)
NO_VARIABLES(fmi3SetInt32, fmi3Int32, const)
NO_VARIABLES(fmi3SetUInt32, fmi3UInt32, const)
NO_VARIABLES(fmi3SetInt64, fmi3Int64, const)
NO_VARIABLES(fmi3SetUInt64, fmi3UInt64, const)
NO_VARIABLES(fmi3SetString, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return st3(no_variables(instance, nvr, "fmi3GetBinary"));
}
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return st3(no_variables(instance, nvr, "fmi3SetBinary"));
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)values;
    return st3(no_variables(instance, nvr, "fmi3GetClock"));
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr; (void)values;
    return st3(no_variables(instance, nvr, "fmi3SetClock"));
}

/* ---- dependencies: not provided (the modelDescription's ModelStructure has them) ---- */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies");
}

/* ---- FMU state: mpc_native.c's (a checked copy of the model) ---- */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return st3(fmi2GetFMUstate(instance, FMUState));
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    return st3(fmi2SetFMUstate(instance, FMUState));
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return st3(fmi2FreeFMUstate(instance, FMUState));
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    return st3(fmi2SerializedFMUstateSize(instance, FMUState, size));
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    return st3(fmi2SerializeFMUstate(instance, FMUState, (fmi2Byte *)serializedState, size));
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    return st3(fmi2DeSerializeFMUstate(instance, (const fmi2Byte *)serializedState, size, FMUState));
}

/* ---- derivatives, configuration, clocks, discrete states: not supported ---- */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative (providesDirectionalDerivative false)");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative (providesAdjointDerivatives false)");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode (no structural parameters)");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode (no structural parameters)");
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)intervals; (void)qualifiers;
    return st3(no_variables(instance, nvr, "fmi3GetIntervalDecimal"));
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)counters; (void)resolutions; (void)qualifiers;
    return st3(no_variables(instance, nvr, "fmi3GetIntervalFraction"));
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    (void)vr; (void)shifts;
    return st3(no_variables(instance, nvr, "fmi3GetShiftDecimal"));
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr; (void)counters; (void)resolutions;
    return st3(no_variables(instance, nvr, "fmi3GetShiftFraction"));
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr; (void)intervals;
    return st3(no_variables(instance, nvr, "fmi3SetIntervalDecimal"));
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)counters; (void)resolutions;
    return st3(no_variables(instance, nvr, "fmi3SetIntervalFraction"));
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr; (void)shifts;
    return st3(no_variables(instance, nvr, "fmi3SetShiftDecimal"));
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)counters; (void)resolutions;
    return st3(no_variables(instance, nvr, "fmi3SetShiftFraction"));
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates");
}
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    return unsupported(instance, "fmi3UpdateDiscreteStates (hasEventMode false)");
}

/* ---- co-simulation ---- */
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { return instance ? fmi3OK : fmi3Error; }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    return unsupported(instance, "fmi3GetOutputDerivatives (maxOutputDerivativeOrder 0)");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    if (!instance) return fmi3Error;
    fmi2Status s = fmi2DoStep(instance, currentCommunicationPoint, communicationStepSize,
                              noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False);
    if (eventHandlingNeeded) *eventHandlingNeeded = false;
    if (terminateSimulation) *terminateSimulation = false;
    if (earlyReturn) *earlyReturn = false;
    if (lastSuccessfulTime) *lastSuccessfulTime = ((Instance *)instance)->m.t;
    return st3(s);
}

/* ---- model exchange and scheduled execution: not this FMU's interfaces (no instance can exist) ---- */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterContinuousTimeMode");
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return unsupported(instance, "fmi3CompletedIntegratorStep");
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return unsupported(instance, "fmi3SetTime");
}
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "fmi3SetContinuousStates");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStateDerivatives");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    (void)eventIndicators; (void)nEventIndicators;
    return unsupported(instance, "fmi3GetEventIndicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetContinuousStates");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals; (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNominalsOfContinuousStates");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return unsupported(instance, "fmi3GetNumberOfEventIndicators");
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return unsupported(instance, "fmi3GetNumberOfContinuousStates");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition");
}
