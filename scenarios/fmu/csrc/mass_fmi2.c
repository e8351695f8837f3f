/* FMI 2.0 co-simulation and model-exchange FMU of mass_core.h. Built with -DMASS_STATE=0 the
 * FMU state functions fail (and the model description says it cannot save state). */
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"
#include "mass_core.h"

#ifndef MASS_STATE
#define MASS_STATE 1
#endif

typedef struct {
    MassData d;
    fmi2CallbackFunctions cb;
    char name[64];
} Instance;

static fmi2Status fail(Instance *inst, const char *msg) {
    if (inst && inst->cb.logger) inst->cb.logger(inst->cb.componentEnvironment, inst->name, fmi2Error, "error", msg);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    (void)type; (void)guid; (void)resources; (void)visible; (void)logging;
    Instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    mass_defaults(&inst->d);
    if (functions) inst->cb = *functions;
    snprintf(inst->name, sizeof inst->name, "%s", name ? name : "mass");
    return inst;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Instance *)c)->d.time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = c;
    return mass_initialize(&inst->d) == 0 ? fmi2OK : fail(inst, "m and k must be positive");
}

fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = c;
    mass_defaults(&inst->d);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Instance *inst = c;
    for (size_t i = 0; i < n; i++)
        if (mass_get(&inst->d, vr[i], &value[i]) != 0) return fail(inst, "unknown value reference");
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Instance *inst = c;
    for (size_t i = 0; i < n; i++)
        if (mass_set(&inst->d, vr[i], value[i]) != 0) return fail(inst, "variable cannot be set now");
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    Instance *inst = c;
    if (!MASS_STATE) return fail(inst, "this FMU cannot save its state");
    if (*s == NULL) *s = malloc(sizeof(MassData));
    if (*s == NULL) return fail(inst, "out of memory");
    memcpy(*s, &inst->d, sizeof(MassData));
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    Instance *inst = c;
    if (!MASS_STATE || s == NULL) return fail(inst, "no state to set");
    memcpy(&inst->d, s, sizeof(MassData));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c;
    free(*s);
    *s = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    (void)s;
    if (!MASS_STATE) return fail(c, "this FMU cannot serialize its state");
    *size = sizeof(MassData);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte bytes[], size_t size) {
    if (!MASS_STATE || size != sizeof(MassData)) return fail(c, "cannot serialize");
    memcpy(bytes, s, size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *s) {
    Instance *inst = c;
    MassData d;
    if (!MASS_STATE || size != sizeof(MassData)) return fail(inst, "serialized state has the wrong size");
    memcpy(&d, bytes, size);
    if (d.magic != MASS_MAGIC) return fail(inst, "not a serialized mass state");
    if (*s == NULL) *s = malloc(sizeof(MassData));
    if (*s == NULL) return fail(inst, "out of memory");
    memcpy(*s, &d, size);
    return fmi2OK;
}

/* co-simulation */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *inst = c;
    (void)noSetPrior;
    if (!(h >= 0.0)) return fail(inst, "negative step");
    if (mass_discards(h)) { /* nothing stepped */
        if (inst->cb.logger) inst->cb.logger(inst->cb.componentEnvironment, inst->name, fmi2Discard, "logStatusDiscard",
                                             MASS_DISCARD_MESSAGE);
        return fmi2Discard;
    }
    inst->d.time = t;
    mass_step(&inst->d, h);
    if (mass_warns(t)) {
        if (inst->cb.logger) inst->cb.logger(inst->cb.componentEnvironment, inst->name, fmi2Warning, "logStatusWarning",
                                             MASS_WARN_MESSAGE);
        return fmi2Warning;
    }
    return fmi2OK;
}

/* model exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    (void)c;
    memset(info, 0, sizeof *info);
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }

/* Built with MASS_STEP_EVENT_AT = t >= 0, model exchange asks for event mode at the first completed integrator step
   at or after t (a step event: the environment must ask after every step to see it in time). */
#ifndef MASS_STEP_EVENT_AT
#define MASS_STEP_EVENT_AT -1.0
#endif

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetPrior, fmi2Boolean *enterEvent,
                                       fmi2Boolean *terminate) {
    (void)noSetPrior;
    double at = MASS_STEP_EVENT_AT;
    *enterEvent = (at >= 0.0 && ((Instance *)c)->d.time >= at) ? fmi2True : fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Instance *)c)->d.time = t; return fmi2OK; }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    inst->d.u = x[0];
    inst->d.v = x[1];
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    x[0] = inst->d.u;
    x[1] = inst->d.v;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Instance *inst = c;
    if (nx != 2) return fail(inst, "two continuous states");
    mass_get(&inst->d, 7, &dx[0]);
    mass_get(&inst->d, 8, &dx[1]);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    (void)c; (void)z;
    return nz == 0 ? fmi2OK : fmi2Error;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real nominal[], size_t nx) {
    (void)c;
    for (size_t i = 0; i < nx; i++) nominal[i] = 1.0;
    return fmi2OK;
}
