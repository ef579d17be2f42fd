/* nd_jitter: allocation-free statistics of a periodic loop's wake-up error.
 * Samples go into a fixed histogram (1 us bins to 2 ms, then 100 us bins to 100 ms,
 * then one overflow bin), so recording is O(1) and safe inside a 1 kHz loop. */
#ifndef ND_JITTER_H
#define ND_JITTER_H

#include <stdint.h>

#define ND_JITTER_FINE 2000                /* 1 us bins: [0, 2000) us */
#define ND_JITTER_COARSE 980               /* 100 us bins: [2000, 100000) us */
#define ND_JITTER_BINS (ND_JITTER_FINE + ND_JITTER_COARSE + 1)

typedef struct {
  uint32_t bins[ND_JITTER_BINS];
  int64_t count;
  int64_t overruns;   /* cycles whose error was at least one period */
  double max_us;
} nd_jitter;

/* Zero all statistics. */
void nd_jitter_reset(nd_jitter *j);

/* Record one wake-up error (late by err_us >= 0; negative counts as 0) of a loop with
 * period period_us. */
void nd_jitter_add(nd_jitter *j, double err_us, double period_us);

/* q-quantile (0..1) of the recorded errors in us, to bin resolution; 0 if empty. */
double nd_jitter_quantile(const nd_jitter *j, double q);

#endif
