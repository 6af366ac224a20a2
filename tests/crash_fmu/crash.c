/* A Co-Simulation FMU (FMI 2.0) that misbehaves on purpose: y = p * t, and its step function
   crashes (writes through a null pointer) when p > 1.5 and never returns when p < 0.1. */
#include <stddef.h>
#include <stdlib.h>

typedef void (*Logger)(void *, const char *, int, const char *, const char *, ...);
typedef struct { Logger logger; void *allocate; void *free; void *step_finished; void *env; } Callbacks;
typedef struct { double p, t; Logger log; void *env; } Instance;

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const Callbacks *cb, int visible, int logging) {
    Instance *s = calloc(1, sizeof(Instance));
    s->p = 1.0; s->log = cb->logger; s->env = cb->env;
    return s;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    ((Instance *)c)->t = start; return 0;
}
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) { return 0; }
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) { Instance *s = c; s->p = 1.0; s->t = 0.0; return 0; }
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) { if (vr[i] != 1) return 3; s->p = v[i]; }
    return 0;
}
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) v[i] = vr[i] == 1 ? s->p : s->p * s->t;
    return 0;
}
int fmi2DoStep(void *c, double t, double h, int no_set_prior) {
    Instance *s = c;
    if (s->p > 1.5) {
        s->log(s->env, "crash", 3, "logStatusError", "p is above 1.5: crashing on purpose");
        *(volatile int *)0 = 1;
    }
    if (s->p < 0.1) {
        for (;;) {}
    }
    s->t = t + h;
    return 0;
}
