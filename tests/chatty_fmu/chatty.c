/* A chatty FMU (FMI 2.0, Model Exchange and Co-Simulation): x' = -k x, x(0) = x0, so
   x(t) = x0 exp(-k t). Its native code prints to stdout and stderr (printf, puts, fprintf,
   write) while it instantiates, steps and gives derivatives, and logs through the FMI 2.0
   logger with printf-style arguments. The parameter `mode` makes it misbehave:
   1: print its last words and crash (a write through a null pointer) at its first step or
      derivative;
   2: print megabytes to stdout at its first step or derivative (one line far too long,
      then many ordinary ones), then go on normally;
   3: refuse its first step or derivative (fmi2Error), saying why through the logger. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef void (*Logger)(void *, const char *, int, const char *, const char *, ...);
typedef struct { Logger logger; void *allocate; void *free; void *step_finished; void *env; } Callbacks;
typedef struct {
    double k, x0, mode, x, t;
    int cs, spoke;
    Logger log;
    void *env;
    char name[64];
} Instance;

static int misbehave(Instance *s, const char *where) {
    if (s->spoke) return 0;
    s->spoke = 1;
    printf("chatty says from %s at t=%g\n", where, s->t);
    fprintf(stderr, "chatty warns on stderr from %s\n", where);
    s->log(s->env, s->name, 0, "logAll", "%s at t = %g, k = %g", where, s->t, s->k);
    if (s->mode == 1.0) {
        puts("chatty: last words before the crash");
        fprintf(stderr, "chatty: crashing on purpose in %s\n", where);
        *(volatile int *)0 = 1;
    }
    if (s->mode == 2.0) {
        /* One line of 3 MB, then 100000 lines of 80 characters: 11 MB in all. */
        static char line[3 << 20];
        memset(line, 'z', sizeof line - 1);
        line[sizeof line - 1] = '\0';
        puts(line);
        for (int i = 0; i < 100000; i++) printf("chatty flood line %07d %s\n", i, "................................................");
        fflush(stdout);
    }
    if (s->mode == 3.0) {
        s->log(s->env, s->name, 3, "logStatusError", "%s refused at t = %g: k = %.3f is %d%% too %s",
               where, s->t, s->k, 50, "chatty");
        return 3;
    }
    return 0;
}

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const Callbacks *cb, int visible, int logging) {
    Instance *s = calloc(1, sizeof(Instance));
    s->k = 0.5; s->x0 = 1.0; s->x = 1.0; s->cs = type == 1;
    s->log = cb->logger; s->env = cb->env;
    snprintf(s->name, sizeof s->name, "%s", name);
    printf("chatty instantiated as %s\n", name);
    fflush(stdout);
    (void)!write(1, "chatty writes to fd 1\n", 22);
    fprintf(stderr, "chatty instantiated, said on stderr\n");
    s->log(s->env, name, 0, "logAll",
           "instantiated %s: %d %i %u %ld %lld %zu %x %c %g %f %e 100%% #r1#", name, -7, 42,
           3000000000u, -1234567890123L, 9876543210123LL, (size_t)77, 255u, 'Q', 0.5, 2.25, 1e-3);
    s->log(s->env, name, 1, "logStatusWarning", "a warning about %s", "nothing");
    return s;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    ((Instance *)c)->t = start; return 0;
}
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) { Instance *s = c; s->x = s->x0; return 0; }
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) {
    Instance *s = c;
    s->k = 0.5; s->x0 = 1.0; s->x = 1.0; s->mode = 0; s->t = 0; s->spoke = 0;
    return 0;
}
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 1: s->k = v[i]; break;
        case 2: s->x0 = v[i]; break;
        case 3: s->mode = v[i]; break;
        default: return 3;
        }
    }
    return 0;
}
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 0: v[i] = s->t; break;
        case 1: v[i] = s->k; break;
        case 2: v[i] = s->x0; break;
        case 3: v[i] = s->mode; break;
        case 4: v[i] = s->x; break;
        case 5: v[i] = -s->k * s->x; break;
        default: return 3;
        }
    }
    return 0;
}
int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *v) { return n == 0 ? 0 : 3; }
int fmi2GetBoolean(void *c, const unsigned *vr, size_t n, int *v) { return n == 0 ? 0 : 3; }
int fmi2DoStep(void *c, double t, double h, int no_set_prior) {
    Instance *s = c;
    if (misbehave(s, "doStep")) return 3;
    s->x *= exp(-s->k * h);
    s->t = t + h;
    return 0;
}
int fmi2GetBooleanStatus(void *c, int kind, int *v) { *v = 0; return 0; }

/* Model Exchange */
int fmi2EnterEventMode(void *c) { return 0; }
int fmi2EnterContinuousTimeMode(void *c) { return 0; }
int fmi2NewDiscreteStates(void *c, int *info) {
    /* newDiscreteStatesNeeded, terminateSimulation, nominalsChanged, valuesChanged,
       nextEventTimeDefined: all false. */
    for (int i = 0; i < 5; i++) info[i] = 0;
    return 0;
}
int fmi2CompletedIntegratorStep(void *c, int no_set_prior, int *enter_event, int *terminate) {
    *enter_event = 0; *terminate = 0; return 0;
}
int fmi2SetTime(void *c, double t) { ((Instance *)c)->t = t; return 0; }
int fmi2SetContinuousStates(void *c, const double *x, size_t n) { ((Instance *)c)->x = x[0]; return 0; }
int fmi2GetContinuousStates(void *c, double *x, size_t n) { x[0] = ((Instance *)c)->x; return 0; }
int fmi2GetDerivatives(void *c, double *dx, size_t n) {
    Instance *s = c;
    if (misbehave(s, "getDerivatives")) return 3;
    dx[0] = -s->k * s->x;
    return 0;
}
int fmi2GetEventIndicators(void *c, double *z, size_t n) { return 0; }
int fmi2GetNominalsOfContinuousStates(void *c, double *x, size_t n) { x[0] = 1.0; return 0; }
