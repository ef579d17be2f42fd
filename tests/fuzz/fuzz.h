/* Shared by the fuzz targets (tests/fuzz/fuzz_*.c).
 *
 * Each target is a libFuzzer entry point, LLVMFuzzerTestOneInput, linked either with
 * libFuzzer (NUDGE_FUZZ builds, clang) or with fuzz_main.c, which replays corpus and
 * regression files under ctest. A broken invariant aborts: libFuzzer saves the input as a
 * crash, the replay driver dies and its test fails. */
#ifndef ND_FUZZ_H
#define ND_FUZZ_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Called before a broken invariant aborts (atexit handlers do not run then): a target
 * that keeps scratch files removes them here. */
static void (*fz_on_abort)(void) __attribute__((unused));

/* For a target's reference model: it is not under test, so it gets no coverage
 * instrumentation (clang; GCC's replay builds have none anyway). It then runs at full
 * speed, and its branches, which mirror the code under test, add no features of their
 * own that would steer the fuzzer. The sanitizers still check it. */
#if defined(__clang__)
#define FZ_ORACLE __attribute__((no_sanitize("coverage")))
#else
#define FZ_ORACLE
#endif

#define FZ_CHECK(cond, ...)                                                         \
  do {                                                                              \
    if (!(cond)) {                                                                  \
      fprintf(stderr, "%s:%d: invariant broken: %s: ", __FILE__, __LINE__, #cond);  \
      fprintf(stderr, __VA_ARGS__);                                                 \
      fputc('\n', stderr);                                                          \
      if (fz_on_abort) fz_on_abort();                                               \
      abort();                                                                      \
    }                                                                               \
  } while (0)

#endif
