/* nd_stats: sort, then read off. */
#include "nd_stats.h"

#include <math.h>
#include <stdlib.h>

static int cmp_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

nd_stats nd_stats_of(double *v, int n) {
  nd_stats s = {0, NAN, NAN, NAN, NAN, NAN};
  int k = 0;
  for (int i = 0; i < n; i++)
    if (isfinite(v[i])) v[k++] = v[i];
  if (!k) return s;
  qsort(v, k, sizeof(double), cmp_double);
  double sum = 0, ss = 0;
  for (int i = 0; i < k; i++) sum += v[i];
  s.n = k;
  s.mean = sum / k;
  for (int i = 0; i < k; i++) ss += (v[i] - s.mean) * (v[i] - s.mean);
  s.std = k > 1 ? sqrt(ss / (k - 1)) : 0;
  s.min = v[0];
  s.max = v[k - 1];
  s.median = k % 2 ? v[k / 2] : 0.5 * (v[k / 2 - 1] + v[k / 2]);
  return s;
}

double nd_quantile(double *v, int n, double q) {
  if (n < 1) return NAN;
  qsort(v, n, sizeof(double), cmp_double);
  const int i = (int)floor(q * (n - 1) + 0.5);
  return v[i < 0 ? 0 : i >= n ? n - 1 : i];
}
