/* nd_jitter: histogram of loop wake-up errors. */
#include "nd_jitter.h"

#include <string.h>

void nd_jitter_reset(nd_jitter *j) { memset(j, 0, sizeof(*j)); }

void nd_jitter_add(nd_jitter *j, double err_us, double period_us) {
  if (!(err_us > 0.0)) err_us = 0.0;  /* also maps NaN to 0 */
  int b;
  if (err_us < ND_JITTER_FINE) b = (int)err_us;
  else if (err_us < ND_JITTER_FINE + 100.0 * ND_JITTER_COARSE)
    b = ND_JITTER_FINE + (int)((err_us - ND_JITTER_FINE) / 100.0);
  else b = ND_JITTER_BINS - 1;
  j->bins[b]++;
  j->count++;
  if (err_us >= period_us) j->overruns++;
  if (err_us > j->max_us) j->max_us = err_us;
}

double nd_jitter_quantile(const nd_jitter *j, double q) {
  if (j->count == 0) return 0.0;
  int64_t want = (int64_t)(q * (double)(j->count - 1)) + 1, seen = 0;
  for (int b = 0; b < ND_JITTER_BINS; b++) {
    seen += j->bins[b];
    if (seen >= want) {
      if (b < ND_JITTER_FINE) return b;
      if (b < ND_JITTER_BINS - 1) return ND_JITTER_FINE + 100.0 * (b - ND_JITTER_FINE);
      return j->max_us;
    }
  }
  return j->max_us;
}
