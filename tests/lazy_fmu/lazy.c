/* A Model Exchange FMU (FMI 2.0) that computes only when asked for derivatives or event
   indicators, as several exporting tools do: a thermostat whose temperature T rises at 1/s
   while the heater is on and falls at 1.5/s while it is off; the heater switches off when T
   reaches 1 and on when T falls to 0.5 (event indicator 1 - T on, T - 0.5 off).

   - fmi2SetTime and fmi2SetContinuousStates only store; y = 2 T and der(T) are computed in
     fmi2GetDerivatives and fmi2GetEventIndicators, and fmi2GetReal returns what was computed
     last.
   - In event mode the heater switches if the relation computed last (T >= 1 on, T <= 0.5
     off) says so, not the one at the time and states set since.
   - fmi2CompletedIntegratorStep counts the steps (`steps`), asks for event mode every third
     (`requested`; `handled` counts the event modes entered so), and counts the steps that end
     before the previous one (`backwards`).
   - After `max_switches` switches it asks to terminate. */
#include <stddef.h>
#include <stdlib.h>

typedef struct {
    int new_discrete_states_needed, terminate, nominals_changed, values_changed,
        next_event_time_defined;
    double next_event_time;
} EventInfo;

typedef struct {
    double t, T, y, dT, max_switches;
    int on, crossed, switches, pending;
    double steps, requested, handled, backwards, last_t;
} Instance;

static void init(Instance *s) {
    s->t = 0.0; s->T = 0.05; s->y = 0.0; s->dT = 0.0; s->max_switches = 1000.0;
    s->on = 1; s->crossed = 0; s->switches = 0; s->pending = 0;
    s->steps = s->requested = s->handled = s->backwards = 0.0; s->last_t = 0.0;
}

static void evaluate(Instance *s) {
    s->dT = s->on ? 1.0 : -1.5;
    s->y = 2.0 * s->T;
    s->crossed = s->on ? s->T >= 1.0 : s->T <= 0.5;
}

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const void *cb, int visible, int logging) {
    Instance *s = calloc(1, sizeof(Instance));
    if (s) init(s);
    return s;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    ((Instance *)c)->t = start; return 0;
}
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) { evaluate(c); return 0; }
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) { init(c); return 0; }
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) { if (vr[i] != 4) return 3; s->max_switches = v[i]; }
    return 0;
}
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 0: v[i] = s->T; break;
        case 1: v[i] = s->dT; break;
        case 2: v[i] = s->y; break;
        case 3: v[i] = s->on; break;
        case 4: v[i] = s->max_switches; break;
        case 5: v[i] = s->steps; break;
        case 6: v[i] = s->requested; break;
        case 7: v[i] = s->handled; break;
        case 8: v[i] = s->backwards; break;
        default: return 3;
        }
    }
    return 0;
}
int fmi2SetTime(void *c, double t) { ((Instance *)c)->t = t; return 0; }
int fmi2SetContinuousStates(void *c, const double *x, size_t n) {
    ((Instance *)c)->T = x[0]; return 0;
}
int fmi2GetContinuousStates(void *c, double *x, size_t n) { x[0] = ((Instance *)c)->T; return 0; }
int fmi2GetNominalsOfContinuousStates(void *c, double *x, size_t n) { x[0] = 1.0; return 0; }
int fmi2GetDerivatives(void *c, double *dx, size_t n) {
    Instance *s = c;
    evaluate(s);
    dx[0] = s->dT;
    return 0;
}
int fmi2GetEventIndicators(void *c, double *z, size_t n) {
    Instance *s = c;
    evaluate(s);
    z[0] = s->on ? 1.0 - s->T : s->T - 0.5;
    return 0;
}
int fmi2EnterEventMode(void *c) {
    Instance *s = c;
    if (s->pending) { s->handled += 1.0; s->pending = 0; }
    return 0;
}
int fmi2NewDiscreteStates(void *c, EventInfo *info) {
    Instance *s = c;
    info->new_discrete_states_needed = 0;
    info->terminate = 0;
    info->nominals_changed = 0;
    info->values_changed = 0;
    info->next_event_time_defined = 0;
    info->next_event_time = 0.0;
    if (s->crossed) {
        s->on = !s->on;
        s->switches += 1;
        evaluate(s);
        if (s->switches >= s->max_switches) info->terminate = 1;
    }
    return 0;
}
int fmi2EnterContinuousTimeMode(void *c) { return 0; }
int fmi2CompletedIntegratorStep(void *c, int no_set_prior, int *enter_event_mode, int *terminate) {
    Instance *s = c;
    s->steps += 1.0;
    if (s->t < s->last_t) s->backwards += 1.0;
    s->last_t = s->t;
    *enter_event_mode = 0;
    *terminate = 0;
    if ((long)s->steps % 3 == 0) {
        s->requested += 1.0;
        s->pending = 1;
        *enter_event_mode = 1;
    }
    return 0;
}
