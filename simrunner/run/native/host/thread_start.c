/* Linked into every program simrunner builds (build.py, THREAD_START_SOURCE), which is linked
 * with --wrap=pthread_create: the program's pthread_create calls come here, and go on to the host
 * (spinner_host.c, both builds: spinner_thread_create), which starts the thread with an alternate
 * signal stack of its own, so that its stack overflow is reported at its line.
 *
 * This definition has to be in the program itself: an undefined __wrap_pthread_create would be
 * taken from libgcc.a at the link (its split-stack support defines one, for -fsplit-stack), not
 * from the host at the load. */
#include <pthread.h>

#ifdef __cplusplus
extern "C" {
#endif
int spinner_thread_create(pthread_t *thread, const pthread_attr_t *attr, void *(*fn)(void *), void *arg);

int __wrap_pthread_create(pthread_t *thread, const pthread_attr_t *attr, void *(*fn)(void *), void *arg) {
    return spinner_thread_create(thread, attr, fn, arg);
}
#ifdef __cplusplus
}
#endif
