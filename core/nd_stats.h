/* nd_stats: summary statistics of samples, for the programs that print figures. */
#ifndef ND_STATS_H
#define ND_STATS_H

typedef struct {
  int n;             /* finite samples */
  double mean, std;  /* std: sample standard deviation (n - 1), 0 for one sample */
  double min, max, median;
} nd_stats;

/* Statistics of the finite values among v[0, n); v is reordered (the finite values first,
 * sorted). Every field NaN (n 0) when there is none. */
nd_stats nd_stats_of(double *v, int n);

/* The q-quantile (0..1) of v[0, n), nearest rank; v is sorted in place. NaN if n < 1. */
double nd_quantile(double *v, int n, double q);

#endif
