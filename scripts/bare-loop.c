/* The yardstick of scripts/sard-footprint.sh: a bare loop of
 * clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) at 1 kHz, nothing else.
 * Usage: bare-loop CYCLES; prints the CPU time it used (user + system, s). */
#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <time.h>

int main(int argc, char **argv) {
    long n = argc > 1 ? atol(argv[1]) : 1000;
    struct timespec t;
    struct rusage u;
    clock_gettime(CLOCK_MONOTONIC, &t);
    for (long i = 0; i < n; i++) {
        t.tv_nsec += 1000000;
        if (t.tv_nsec >= 1000000000) {
            t.tv_nsec -= 1000000000;
            t.tv_sec++;
        }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &t, 0);
    }
    getrusage(RUSAGE_SELF, &u);
    printf("%.3f\n", u.ru_utime.tv_sec + u.ru_utime.tv_usec / 1e6 + u.ru_stime.tv_sec +
                         u.ru_stime.tv_usec / 1e6);
    return 0;
}
