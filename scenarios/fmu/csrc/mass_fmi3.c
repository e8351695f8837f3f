/* FMI 3.0 co-simulation and model-exchange FMU of mass_core.h (value reference = index + 1;
 * 0 is time). Built with -DMASS_STATE=0 the FMU state functions fail. */
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"
#include "mass_core.h"

#ifndef MASS_STATE
#define MASS_STATE 1
#endif

typedef struct {
    MassData d;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

static fmi3Status fail(Instance *inst, const char *msg) {
    if (inst && inst->log) inst->log(inst->env, fmi3Error, "error", msg);
    return fmi3Error;
}

static Instance *make(fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    mass_defaults(&inst->d);
    inst->env = env;
    inst->log = log;
    return inst;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
                                          fmi3Boolean logging, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback log) {
    (void)name; (void)token; (void)resources; (void)visible; (void)logging;
    return make(env, log);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
                                         fmi3Boolean logging, fmi3Boolean eventModeUsed, fmi3Boolean earlyReturn,
                                         const fmi3ValueReference required[], size_t nRequired,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                         fmi3IntermediateUpdateCallback update) {
    (void)name; (void)token; (void)resources; (void)visible; (void)logging; (void)eventModeUsed;
    (void)earlyReturn; (void)required; (void)nRequired; (void)update;
    return make(env, log);
}

void fmi3FreeInstance(fmi3Instance c) { free(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDefined, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stopDefined, fmi3Float64 stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Instance *)c)->d.time = start;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    Instance *inst = c;
    return mass_initialize(&inst->d) == 0 ? fmi3OK : fail(inst, "m and k must be positive");
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { (void)c; return fmi3OK; }

fmi3Status fmi3Reset(fmi3Instance c) {
    mass_defaults(&((Instance *)c)->d);
    return fmi3OK;
}

/* Built with MASS_F32, v (value reference 2) and F (3) are Float32 variables: like a strict FMU, the Float64
   calls refuse them and the Float32 calls take only them. */
#ifndef MASS_F32
#define MASS_F32 0
#endif
static int is_f32(fmi3ValueReference vr) { return MASS_F32 && (vr == 2 || vr == 3); }

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 values[],
                          size_t nValues) {
    Instance *inst = c;
    if (nValues != n) return fail(inst, "scalar variables only");
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == 0) { values[i] = inst->d.time; continue; }
        if (is_f32(vr[i])) return fail(inst, "fmi3GetFloat64 called for a Float32 variable");
        if (mass_get(&inst->d, vr[i] - 1, &values[i]) != 0) return fail(inst, "unknown value reference");
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 values[],
                          size_t nValues) {
    Instance *inst = c;
    if (nValues != n) return fail(inst, "scalar variables only");
    for (size_t i = 0; i < n; i++) {
        if (is_f32(vr[i])) return fail(inst, "fmi3SetFloat64 called for a Float32 variable");
        if (vr[i] == 0 || mass_set(&inst->d, vr[i] - 1, values[i]) != 0) return fail(inst, "cannot be set now");
    }
    return fmi3OK;
}

fmi3Status fmi3GetFloat32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float32 values[],
                          size_t nValues) {
    Instance *inst = c;
    if (nValues != n) return fail(inst, "scalar variables only");
    for (size_t i = 0; i < n; i++) {
        double x;
        if (!is_f32(vr[i])) return fail(inst, "fmi3GetFloat32 called for a variable that is not Float32");
        if (mass_get(&inst->d, vr[i] - 1, &x) != 0) return fail(inst, "unknown value reference");
        values[i] = (fmi3Float32)x;
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat32(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float32 values[],
                          size_t nValues) {
    Instance *inst = c;
    if (nValues != n) return fail(inst, "scalar variables only");
    for (size_t i = 0; i < n; i++) {
        if (!is_f32(vr[i])) return fail(inst, "fmi3SetFloat32 called for a variable that is not Float32");
        if (mass_set(&inst->d, vr[i] - 1, (double)values[i]) != 0) return fail(inst, "cannot be set now");
    }
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s) {
    Instance *inst = c;
    if (!MASS_STATE) return fail(inst, "this FMU cannot save its state");
    if (*s == NULL) *s = malloc(sizeof(MassData));
    if (*s == NULL) return fail(inst, "out of memory");
    memcpy(*s, &inst->d, sizeof(MassData));
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s) {
    Instance *inst = c;
    if (!MASS_STATE || s == NULL) return fail(inst, "no state to set");
    memcpy(&inst->d, s, sizeof(MassData));
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s) {
    (void)c;
    free(*s);
    *s = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *size) {
    (void)s;
    if (!MASS_STATE) return fail(c, "this FMU cannot serialize its state");
    *size = sizeof(MassData);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte bytes[], size_t size) {
    if (!MASS_STATE || size != sizeof(MassData)) return fail(c, "cannot serialize");
    memcpy(bytes, s, size);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte bytes[], size_t size, fmi3FMUState *s) {
    Instance *inst = c;
    MassData d;
    if (!MASS_STATE || size != sizeof(MassData)) return fail(inst, "serialized state has the wrong size");
    memcpy(&d, bytes, size);
    if (d.magic != MASS_MAGIC) return fail(inst, "not a serialized mass state");
    if (*s == NULL) *s = malloc(sizeof(MassData));
    if (*s == NULL) return fail(inst, "out of memory");
    memcpy(*s, &d, size);
    return fmi3OK;
}

/* co-simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance c) { (void)c; return fmi3OK; }

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior, fmi3Boolean *eventNeeded,
                      fmi3Boolean *terminate, fmi3Boolean *earlyReturn, fmi3Float64 *lastTime) {
    Instance *inst = c;
    (void)noSetPrior;
    if (!(h >= 0.0)) return fail(inst, "negative step");
    *eventNeeded = fmi3False;
    *terminate = fmi3False;
    *earlyReturn = fmi3False;
    if (mass_discards(h)) { /* nothing stepped */
        *lastTime = t;
        if (inst->log) inst->log(inst->env, fmi3Discard, "logStatusDiscard", MASS_DISCARD_MESSAGE);
        return fmi3Discard;
    }
    inst->d.time = t;
    mass_step(&inst->d, h);
    *lastTime = inst->d.time;
    if (mass_warns(t)) {
        if (inst->log) inst->log(inst->env, fmi3Warning, "logStatusWarning", MASS_WARN_MESSAGE);
        return fmi3Warning;
    }
    return fmi3OK;
}

/* model exchange */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *needUpdate, fmi3Boolean *terminate,
                                    fmi3Boolean *nominalsChanged, fmi3Boolean *valuesChanged,
                                    fmi3Boolean *nextTimeDefined, fmi3Float64 *nextTime) {
    (void)c;
    *needUpdate = *terminate = *nominalsChanged = *valuesChanged = *nextTimeDefined = fmi3False;
    *nextTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { (void)c; return fmi3OK; }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetPrior, fmi3Boolean *enterEvent,
                                       fmi3Boolean *terminate) {
    (void)c; (void)noSetPrior;
    *enterEvent = *terminate = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 t) { ((Instance *)c)->d.time = t; return fmi3OK; }

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    inst->d.u = x[0];
    inst->d.v = x[1];
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    x[0] = inst->d.u;
    x[1] = inst->d.v;
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    mass_get(&inst->d, 7, &dx[0]);
    mass_get(&inst->d, 8, &dx[1]);
    return fmi3OK;
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t nz) {
    (void)c; (void)z;
    return nz == 0 ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominal[], size_t nx) {
    (void)c;
    for (size_t i = 0; i < nx; i++) nominal[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n) { (void)c; *n = 0; return fmi3OK; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n) { (void)c; *n = 2; return fmi3OK; }
