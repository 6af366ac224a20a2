/* A Co-Simulation FMU (FMI 2.0) that tries to get out of its process and its folder, for
   the tests of what confines an FMU's code. Its parameter `mode` says what it tries when
   it is initialised, its output `y` what came of it:
     1  start a process that leaves (fork, fork again, setsid, the middle one exits), named
        MARKER, that sleeps forever: y = its pid;
     2  the same, then never return (the deadline stops it);
     3  write the file OUTSIDE (outside its folders): y = 1 when it could, plus 2 when it
        could write a file in its working folder;
     4  read the file SECRET (outside its folders): y = 1 when it could;
     5  allocate 6 GiB (not touched): y = 1 when it could;
     6  y = the pid of its parent process (the supervisor, whose working folder it has). */
#define _GNU_SOURCE
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>

#ifndef MARKER
#define MARKER "calib-escape"
#endif
#ifndef OUTSIDE
#define OUTSIDE "/tmp/calib-escape-outside"
#endif
#ifndef SECRET
#define SECRET "/etc/hostname"
#endif

typedef void (*Logger)(void *, const char *, int, const char *, const char *, ...);
typedef struct { Logger logger; void *allocate; void *free; void *step_finished; void *env; } Callbacks;
typedef struct { double mode, y, t; } Instance;

static double leave(void) {
    int fds[2];
    if (pipe(fds) != 0) return -1;
    pid_t middle = fork();
    if (middle == 0) {
        pid_t away = fork();
        if (away == 0) {
            setsid();
            prctl(PR_SET_NAME, MARKER, 0, 0, 0);
            signal(SIGTERM, SIG_IGN);
            signal(SIGHUP, SIG_IGN);
            for (;;) pause();
        }
        (void)!write(fds[1], &away, sizeof away);
        _exit(0);
    }
    pid_t away = -1;
    (void)!read(fds[0], &away, sizeof away);
    waitpid(middle, NULL, 0);
    close(fds[0]);
    close(fds[1]);
    return (double)away;
}

static double attempt(int mode) {
    switch (mode) {
    case 1: return leave();
    case 2: leave(); for (;;) pause();
    case 3: {
        double y = 0;
        FILE *f = fopen(OUTSIDE, "w");
        if (f) { fputs("written by an FMU\n", f); fclose(f); y += 1; }
        f = fopen("scratch.txt", "w");
        if (f) { fputs("an FMU's own file\n", f); fclose(f); y += 2; }
        return y;
    }
    case 4: {
        FILE *f = fopen(SECRET, "r");
        if (!f) return 0;
        char c;
        size_t n = fread(&c, 1, 1, f);
        fclose(f);
        return n == 1 ? 1 : 0;
    }
    case 5: {
        void *p = malloc((size_t)6 << 30);
        if (!p) return 0;
        free(p);
        return 1;
    }
    case 6: return (double)getppid();
    default: return -1;
    }
}

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const Callbacks *cb, int visible, int logging) {
    return calloc(1, sizeof(Instance));
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    ((Instance *)c)->t = start; return 0;
}
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) {
    Instance *s = c;
    s->y = attempt((int)s->mode);
    return 0;
}
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) { Instance *s = c; s->mode = 0; s->y = 0; s->t = 0; return 0; }
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) { if (vr[i] != 1) return 3; s->mode = v[i]; }
    return 0;
}
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Instance *s = c;
    for (size_t i = 0; i < n; i++) v[i] = vr[i] == 1 ? s->mode : s->y;
    return 0;
}
int fmi2DoStep(void *c, double t, double h, int no_set_prior) {
    ((Instance *)c)->t = t + h;
    return 0;
}
