/* nds_reach: the arm's joint-limit load over the table (contract in nds_reach.h). */
#include "nds_reach.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"

int nds_reach_build(nds_reach *r, const nds_panda_cfg *cfg, const double lo[2],
                    const double hi[2], double step, char *err, int errlen) {
  memset(r, 0, sizeof(*r));
  if (!nd_all_finite(lo, 2) || !nd_all_finite(hi, 2) || !(hi[0] > lo[0]) || !(hi[1] > lo[1]) ||
      !(step > 0.0) || (hi[0] - lo[0]) / step > 1000.0 || (hi[1] - lo[1]) / step > 1000.0) {
    snprintf(err, errlen, "reach: box (%g, %g)..(%g, %g) at step %g m is not a map of at "
             "most 1000 x 1000 cells", lo[0], lo[1], hi[0], hi[1], step);
    return -1;
  }
  r->lo[0] = lo[0], r->lo[1] = lo[1], r->step = step;
  r->nx = (int)ceil((hi[0] - lo[0]) / step) + 1;
  r->ny = (int)ceil((hi[1] - lo[1]) / step) + 1;
  r->vr = malloc(sizeof(float) * 2 * r->nx * r->ny);
  if (!r->vr) {
    snprintf(err, errlen, "reach: out of memory for %d x %d cells", r->nx, r->ny);
    return -1;
  }
  r->ar = r->vr + r->nx * r->ny;
  /* Row by row, each cell seeded from its solved neighbour: IK follows one branch of the
   * arm's self-motion across the table, as the impedance controller's null space does. */
  double row_seed[NDS_PANDA_NJ], seed[NDS_PANDA_NJ], q[NDS_PANDA_NJ];
  memcpy(row_seed, cfg->q_rest, sizeof(row_seed));
  char why[160];
  for (int iy = 0; iy < r->ny; iy++) {
    memcpy(seed, row_seed, sizeof(seed));
    for (int ix = 0; ix < r->nx; ix++) {
      const double target[3] = {lo[0] + ix * step, lo[1] + iy * step,
                                nds_panda_push_height(cfg)};
      const int c = iy * r->nx + ix;
      if (nds_panda_ik(cfg, target, seed, q, why, sizeof(why))) {
        r->vr[c] = r->ar[c] = INFINITY;
        r->unreachable++;
        continue;
      }
      memcpy(seed, q, sizeof(seed));
      if (ix == 0) memcpy(row_seed, q, sizeof(row_seed));
      r->vr[c] = (float)nds_panda_speed_ratio(cfg, q, 1.0);
      r->ar[c] = (float)nds_panda_accel_ratio(cfg, q, 1.0);
    }
  }
  return 0;
}

void nds_reach_free(nds_reach *r) {
  free(r->vr);
  memset(r, 0, sizeof(*r));
}

double nds_reach_load(const nds_reach *r, const double p[2], double v, double a) {
  const double fx = (p[0] - r->lo[0]) / r->step, fy = (p[1] - r->lo[1]) / r->step;
  if (!(fx >= 0.0 && fy >= 0.0 && fx <= r->nx - 1 && fy <= r->ny - 1)) return INFINITY;
  int ix = (int)fx, iy = (int)fy;
  if (ix > r->nx - 2) ix = r->nx - 2;
  if (iy > r->ny - 2) iy = r->ny - 2;
  if (ix < 0) ix = 0;
  if (iy < 0) iy = 0;
  const double u = fx - ix, w = fy - iy;
  const int c = iy * r->nx + ix, nx = r->nx > 1 ? 1 : 0, ny = r->ny > 1 ? r->nx : 0;
  /* Bilinear; an unreachable corner makes the whole cell unreachable. */
  const double vr = (1 - w) * ((1 - u) * r->vr[c] + u * r->vr[c + nx]) +
                    w * ((1 - u) * r->vr[c + ny] + u * r->vr[c + ny + nx]);
  const double ar = (1 - w) * ((1 - u) * r->ar[c] + u * r->ar[c + nx]) +
                    w * ((1 - u) * r->ar[c + ny] + u * r->ar[c + ny + nx]);
  if (!isfinite(vr) || !isfinite(ar)) return INFINITY;
  return fmax(v * vr, a * ar);
}
