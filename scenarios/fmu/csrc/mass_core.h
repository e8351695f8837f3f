/* One mass on a spring to ground, driven by an external force:  m u'' = -k u + F.
 *
 * The physics shared by the FMI 2 and FMI 3 test FMUs (mass_fmi2.c, mass_fmi3.c). Co-simulation
 * steps are exact for a force held constant over the step, so the only discretization error of a
 * coupled run is the zero-order hold of the coupling force at the communication points.
 *
 * Variable indices (FMI 2 value reference = index; FMI 3 value reference = index + 1, 0 is time):
 *   0 u  output, 1 v  output, 2 F  input, 3 m, 4 k, 5 u0, 6 v0  parameters, 7 der(u), 8 der(v).
 */
#ifndef MASS_CORE_H
#define MASS_CORE_H

#include <math.h>
#include <string.h>

#define MASS_MAGIC 0x4d415353u /* "MASS" */
#define MASS_NVARS 9

typedef struct {
    unsigned magic;
    int initialized;
    double time, u, v, F, m, k, u0, v0;
} MassData;

static void mass_defaults(MassData *d) {
    memset(d, 0, sizeof *d);
    d->magic = MASS_MAGIC;
    d->m = 1.0;
    d->k = 4.0 * M_PI * M_PI;
}

static int mass_get(const MassData *d, unsigned idx, double *out) {
    switch (idx) {
    case 0: *out = d->u; return 0;
    case 1: *out = d->v; return 0;
    case 2: *out = d->F; return 0;
    case 3: *out = d->m; return 0;
    case 4: *out = d->k; return 0;
    case 5: *out = d->u0; return 0;
    case 6: *out = d->v0; return 0;
    case 7: *out = d->v; return 0;
    case 8: *out = (d->F - d->k * d->u) / d->m; return 0;
    default: return -1;
    }
}

/* Returns -1 for an unknown index, -2 for a variable that may not be set now. */
static int mass_set(MassData *d, unsigned idx, double value) {
    if (idx == 2) { d->F = value; return 0; }
    if (idx >= 3 && idx <= 6) {
        if (d->initialized) return -2; /* parameters are fixed after initialization */
        if (idx == 3) d->m = value;
        if (idx == 4) d->k = value;
        if (idx == 5) d->u0 = value;
        if (idx == 6) d->v0 = value;
        return 0;
    }
    return idx < MASS_NVARS ? -2 : -1;
}

static int mass_initialize(MassData *d) {
    if (!(d->m > 0.0) || !(d->k > 0.0)) return -1;
    d->u = d->u0;
    d->v = d->v0;
    d->initialized = 1;
    return 0;
}

/* Test options, set at build time: with MASS_DISCARD_ABOVE = h > 0 a co-simulation step longer than h is discarded,
 * nothing stepped (the caller may try a shorter one); with MASS_WARN_AT = t >= 0 every step from t on logs a warning
 * and returns the Warning status (its result stands). */
#ifndef MASS_DISCARD_ABOVE
#define MASS_DISCARD_ABOVE 0.0
#endif
#ifndef MASS_WARN_AT
#define MASS_WARN_AT -1.0
#endif
#define MASS_DISCARD_MESSAGE "step too long for the spring"
#define MASS_WARN_MESSAGE "spring beyond its rated stroke"

static int mass_discards(double h) { return MASS_DISCARD_ABOVE > 0.0 && h > MASS_DISCARD_ABOVE; }

static int mass_warns(double t) { return MASS_WARN_AT >= 0.0 && t >= MASS_WARN_AT; }

/* Exact solution over h with F constant: oscillation about u_eq = F / k. */
static void mass_step(MassData *d, double h) {
    double w = sqrt(d->k / d->m), ueq = d->F / d->k;
    double c = cos(w * h), s = sin(w * h), du = d->u - ueq;
    d->u = ueq + du * c + d->v / w * s;
    d->v = -du * w * s + d->v * c;
    d->time += h;
}

#endif
