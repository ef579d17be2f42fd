/* rt_count: counting wrappers for the real-time loops' tests (test_rtloop, test_bridge_loop).
 *
 * A test that includes this header (once, in its one source file) is linked with
 * -Wl,--wrap for the allocator (malloc, calloc, realloc, reallocarray, free,
 * posix_memalign, aligned_alloc, memalign, valloc, strdup, strndup) and for calls that can
 * block or do I/O (write, read, stdio output, poll, sleeps, mutex and condition waits,
 * fsync, lcm_publish): tests/unit/CMakeLists.txt, nd_add_rt_test. --wrap rewrites every
 * reference to X in the objects of the link, the project's static libraries included,
 * into __wrap_X; the wrappers below count calls while a window is open and go on to
 * __real_X.
 *
 * Under ASan the count works the same: ASan replaces malloc by interposing its own at run
 * time, behind the symbol the wrappers reach as __real_malloc; the link-time rewrite of the
 * callers is untouched. What --wrap cannot see: calls made inside shared libraries (libc
 * itself, MuJoCo: its mj_step works in mjData's preallocated arena). Define _GNU_SOURCE
 * before any include. */
#ifndef RT_COUNT_H
#define RT_COUNT_H

#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <lcm/lcm.h>

enum {
  C_MALLOC, C_CALLOC, C_REALLOC, C_REALLOCARRAY, C_FREE, C_POSIX_MEMALIGN, C_ALIGNED_ALLOC,
  C_MEMALIGN, C_VALLOC, C_STRDUP, C_STRNDUP, N_ALLOC_FN,
  C_WRITE = N_ALLOC_FN, C_READ, C_PRINTF, C_FPRINTF, C_VPRINTF, C_VFPRINTF, C_PUTS, C_FPUTS,
  C_FWRITE, C_PUTCHAR, C_FPUTC, C_FFLUSH, C_POLL, C_NANOSLEEP, C_CLOCK_NANOSLEEP, C_USLEEP,
  C_SLEEP, C_MUTEX_LOCK, C_COND_WAIT, C_COND_TIMEDWAIT, C_FSYNC, C_FDATASYNC, C_LCM_PUBLISH,
  N_FN
};

static const char *const fn_name[N_FN] = {
    "malloc", "calloc", "realloc", "reallocarray", "free", "posix_memalign",
    "aligned_alloc", "memalign", "valloc", "strdup", "strndup", "write", "read", "printf",
    "fprintf", "vprintf", "vfprintf", "puts", "fputs", "fwrite", "putchar", "fputc",
    "fflush", "poll", "nanosleep", "clock_nanosleep", "usleep", "sleep",
    "pthread_mutex_lock", "pthread_cond_wait", "pthread_cond_timedwait", "fsync",
    "fdatasync", "lcm_publish"};

/* Single-threaded test: plain ints. */
static int g_window;
static long g_count[N_FN];

static void tally(int fn) {
  if (g_window) g_count[fn]++;
}

static void window_open(void) {
  memset(g_count, 0, sizeof g_count);
  g_window = 1;
}

static void window_close(void) { g_window = 0; }

static long window_sum(int from, int to) {
  long n = 0;
  for (int i = from; i < to; i++) n += g_count[i];
  return n;
}

/* "malloc 2, free 1" for the functions counted in [from, to). */
static void window_list(char *out, size_t cap, int from, int to) {
  size_t k = 0;
  out[0] = '\0';
  for (int i = from; i < to && k < cap; i++)
    if (g_count[i])
      k += (size_t)snprintf(out + k, cap - k, "%s%s %ld", k ? ", " : "", fn_name[i],
                            g_count[i]);
}

void *__real_malloc(size_t n);
void *__real_calloc(size_t n, size_t size);
void *__real_realloc(void *p, size_t n);
void *__real_reallocarray(void *p, size_t n, size_t size);
void __real_free(void *p);
int __real_posix_memalign(void **p, size_t align, size_t n);
void *__real_aligned_alloc(size_t align, size_t n);
void *__real_memalign(size_t align, size_t n);
void *__real_valloc(size_t n);
char *__real_strdup(const char *s);
char *__real_strndup(const char *s, size_t n);

void *__wrap_malloc(size_t n) { tally(C_MALLOC); return __real_malloc(n); }
void *__wrap_calloc(size_t n, size_t size) { tally(C_CALLOC); return __real_calloc(n, size); }
void *__wrap_realloc(void *p, size_t n) { tally(C_REALLOC); return __real_realloc(p, n); }
void *__wrap_reallocarray(void *p, size_t n, size_t size) {
  tally(C_REALLOCARRAY);
  return __real_reallocarray(p, n, size);
}
void __wrap_free(void *p) { tally(C_FREE); __real_free(p); }
int __wrap_posix_memalign(void **p, size_t align, size_t n) {
  tally(C_POSIX_MEMALIGN);
  return __real_posix_memalign(p, align, n);
}
void *__wrap_aligned_alloc(size_t align, size_t n) {
  tally(C_ALIGNED_ALLOC);
  return __real_aligned_alloc(align, n);
}
void *__wrap_memalign(size_t align, size_t n) { tally(C_MEMALIGN); return __real_memalign(align, n); }
void *__wrap_valloc(size_t n) { tally(C_VALLOC); return __real_valloc(n); }
char *__wrap_strdup(const char *s) { tally(C_STRDUP); return __real_strdup(s); }
char *__wrap_strndup(const char *s, size_t n) { tally(C_STRNDUP); return __real_strndup(s, n); }

ssize_t __real_write(int fd, const void *b, size_t n);
ssize_t __real_read(int fd, void *b, size_t n);
int __real_vprintf(const char *fmt, va_list ap);
int __real_vfprintf(FILE *f, const char *fmt, va_list ap);
int __real_puts(const char *s);
int __real_fputs(const char *s, FILE *f);
size_t __real_fwrite(const void *p, size_t size, size_t n, FILE *f);
int __real_putchar(int c);
int __real_fputc(int c, FILE *f);
int __real_fflush(FILE *f);
int __real_poll(struct pollfd *fds, nfds_t n, int timeout);
int __real_nanosleep(const struct timespec *req, struct timespec *rem);
int __real_clock_nanosleep(clockid_t c, int flags, const struct timespec *req,
                           struct timespec *rem);
int __real_usleep(useconds_t us);
unsigned __real_sleep(unsigned s);
int __real_pthread_mutex_lock(pthread_mutex_t *m);
int __real_pthread_cond_wait(pthread_cond_t *c, pthread_mutex_t *m);
int __real_pthread_cond_timedwait(pthread_cond_t *c, pthread_mutex_t *m,
                                  const struct timespec *t);
int __real_fsync(int fd);
int __real_fdatasync(int fd);
int __real_lcm_publish(lcm_t *lcm, const char *ch, const void *data, unsigned int len);

ssize_t __wrap_write(int fd, const void *b, size_t n) { tally(C_WRITE); return __real_write(fd, b, n); }
ssize_t __wrap_read(int fd, void *b, size_t n) { tally(C_READ); return __real_read(fd, b, n); }
int __wrap_vprintf(const char *fmt, va_list ap) { tally(C_VPRINTF); return __real_vprintf(fmt, ap); }
int __wrap_vfprintf(FILE *f, const char *fmt, va_list ap) {
  tally(C_VFPRINTF);
  return __real_vfprintf(f, fmt, ap);
}
int __wrap_printf(const char *fmt, ...) {
  tally(C_PRINTF);
  va_list ap;
  va_start(ap, fmt);
  const int r = __real_vprintf(fmt, ap);
  va_end(ap);
  return r;
}
int __wrap_fprintf(FILE *f, const char *fmt, ...) {
  tally(C_FPRINTF);
  va_list ap;
  va_start(ap, fmt);
  const int r = __real_vfprintf(f, fmt, ap);
  va_end(ap);
  return r;
}
int __wrap_puts(const char *s) { tally(C_PUTS); return __real_puts(s); }
int __wrap_fputs(const char *s, FILE *f) { tally(C_FPUTS); return __real_fputs(s, f); }
size_t __wrap_fwrite(const void *p, size_t size, size_t n, FILE *f) {
  tally(C_FWRITE);
  return __real_fwrite(p, size, n, f);
}
int __wrap_putchar(int c) { tally(C_PUTCHAR); return __real_putchar(c); }
int __wrap_fputc(int c, FILE *f) { tally(C_FPUTC); return __real_fputc(c, f); }
int __wrap_fflush(FILE *f) { tally(C_FFLUSH); return __real_fflush(f); }
int __wrap_poll(struct pollfd *fds, nfds_t n, int timeout) {
  tally(C_POLL);
  return __real_poll(fds, n, timeout);
}
int __wrap_nanosleep(const struct timespec *req, struct timespec *rem) {
  tally(C_NANOSLEEP);
  return __real_nanosleep(req, rem);
}
int __wrap_clock_nanosleep(clockid_t c, int flags, const struct timespec *req,
                           struct timespec *rem) {
  tally(C_CLOCK_NANOSLEEP);
  return __real_clock_nanosleep(c, flags, req, rem);
}
int __wrap_usleep(useconds_t us) { tally(C_USLEEP); return __real_usleep(us); }
unsigned __wrap_sleep(unsigned s) { tally(C_SLEEP); return __real_sleep(s); }
int __wrap_pthread_mutex_lock(pthread_mutex_t *m) {
  tally(C_MUTEX_LOCK);
  return __real_pthread_mutex_lock(m);
}
int __wrap_pthread_cond_wait(pthread_cond_t *c, pthread_mutex_t *m) {
  tally(C_COND_WAIT);
  return __real_pthread_cond_wait(c, m);
}
int __wrap_pthread_cond_timedwait(pthread_cond_t *c, pthread_mutex_t *m,
                                  const struct timespec *t) {
  tally(C_COND_TIMEDWAIT);
  return __real_pthread_cond_timedwait(c, m, t);
}
int __wrap_fsync(int fd) { tally(C_FSYNC); return __real_fsync(fd); }
int __wrap_fdatasync(int fd) { tally(C_FDATASYNC); return __real_fdatasync(fd); }
int __wrap_lcm_publish(lcm_t *lcm, const char *ch, const void *data, unsigned int len) {
  tally(C_LCM_PUBLISH);
  return __real_lcm_publish(lcm, ch, data, len);
}

#endif
