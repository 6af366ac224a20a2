/* The C side of calib's FMU host, compiled by the worker's build script.

   FMI 2.0's logger callback is variadic and printf-style (fmi2CallbackLogger): the message
   is a format and its arguments follow. Stable Rust cannot define a C-variadic function, so
   this one formats the message with vsnprintf and hands the text to the Rust sink at the
   head of the instance environment. FMI 2.0's value-reference escapes (`#r123#`) are left
   as they are. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

/* The head of the instance environment calib passes to fmi2Instantiate. */
typedef struct {
    void (*forward)(void *environment, int status, const char *category, const char *message);
} calib_log_sink;

void calib_fmi2_logger(void *environment, const char *instance, int status,
                       const char *category, const char *format, ...) {
    (void)instance;
    calib_log_sink *sink = environment;
    if (sink == NULL || sink->forward == NULL) return;
    if (format == NULL) {
        sink->forward(environment, status, category, NULL);
        return;
    }
    char small[1024];
    va_list args, again;
    va_start(args, format);
    va_copy(again, args);
    int n = vsnprintf(small, sizeof small, format, args);
    va_end(args);
    if (n < 0) {
        /* Not a format vsnprintf understands: the text as the FMU gave it. */
        sink->forward(environment, status, category, format);
    } else if ((size_t)n < sizeof small) {
        sink->forward(environment, status, category, small);
    } else {
        char *large = malloc((size_t)n + 1);
        if (large != NULL) {
            vsnprintf(large, (size_t)n + 1, format, again);
            sink->forward(environment, status, category, large);
            free(large);
        } else {
            sink->forward(environment, status, category, small);
        }
    }
    va_end(again);
}

/* What the FMU's code writes with printf, puts or fputs reaches the host line by line (not
   when a block fills, or never if the process crashes): stdout line-buffered, stderr
   unbuffered. Called before the FMU's library is loaded. */
void calib_stdio_line_buffered(void) {
    setvbuf(stdout, NULL, _IOLBF, 0);
    setvbuf(stderr, NULL, _IONBF, 0);
}
