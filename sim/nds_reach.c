/* nds_reach: the arm's joint-limit load over the table (contract in nds_reach.h). */
#include "nds_reach.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_exec.h"
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
  r->rate = malloc(sizeof(float) * 2 * NDS_PANDA_NJ * r->nx * r->ny);
  r->slope = malloc(sizeof(float) * 4 * NDS_PANDA_NJ * r->nx * r->ny);
  if (!r->rate || !r->slope) {
    nds_reach_free(r);
    snprintf(err, errlen, "reach: out of memory for %d x %d cells", r->nx, r->ny);
    return -1;
  }
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
      float *cell = r->rate + (size_t)2 * NDS_PANDA_NJ * (iy * r->nx + ix);
      double m[NDS_PANDA_NJ][2];
      if (nds_panda_ik(cfg, target, seed, q, why, sizeof(why)) || nds_panda_rate_map(cfg, q, m)) {
        for (int k = 0; k < 2 * NDS_PANDA_NJ; k++) cell[k] = INFINITY;
        r->unreachable++;
        continue;
      }
      memcpy(seed, q, sizeof(seed));
      if (ix == 0) memcpy(row_seed, q, sizeof(row_seed));
      for (int i = 0; i < NDS_PANDA_NJ; i++) {
        cell[2 * i] = (float)m[i][0];
        cell[2 * i + 1] = (float)m[i][1];
      }
    }
  }
  /* The rates' slopes along x and y at each node: central differences, one-sided at an
   * edge or beside an unreachable node, none (inf) without a neighbour either side. */
  const int K = 2 * NDS_PANDA_NJ;
  for (int iy = 0; iy < r->ny; iy++)
    for (int ix = 0; ix < r->nx; ix++) {
      const int c = iy * r->nx + ix;
      const float *self = r->rate + (size_t)K * c;
      float *sl = r->slope + (size_t)2 * K * c;
      for (int axis = 0; axis < 2; axis++) {
        const int n = axis ? r->ny : r->nx, at = axis ? iy : ix, stride = axis ? r->nx : 1;
        const float *lo_n = at > 0 ? r->rate + (size_t)K * (c - stride) : NULL;
        const float *hi_n = at < n - 1 ? r->rate + (size_t)K * (c + stride) : NULL;
        if (lo_n && !isfinite(lo_n[0])) lo_n = NULL;
        if (hi_n && !isfinite(hi_n[0])) hi_n = NULL;
        for (int j = 0; j < K; j++) {
          float g = INFINITY;
          if (lo_n && hi_n) g = (float)((hi_n[j] - lo_n[j]) / (2 * step));
          else if (hi_n) g = (float)((hi_n[j] - self[j]) / step);
          else if (lo_n) g = (float)((self[j] - lo_n[j]) / step);
          sl[2 * j + axis] = g;
        }
      }
    }
  return 0;
}

int nds_reach_build_ws(nds_reach *r, const double ws_lo[2], const double ws_hi[2], char *err,
                       int errlen) {
  nds_panda_cfg ac;
  nds_panda_cfg_default(&ac);
  const double m = ND_EXEC_WS_MARGIN + 0.01;
  const double lo[2] = {ws_lo[0] - m, ws_lo[1] - m}, hi[2] = {ws_hi[0] + m, ws_hi[1] + m};
  return nds_reach_build(r, &ac, lo, hi, 0.02, err, errlen);
}

void nds_reach_free(nds_reach *r) {
  free(r->rate);
  free(r->slope);
  memset(r, 0, sizeof(*r));
}

int nds_reach_joint(const nds_reach *r, const double p[2], const double v[2],
                    const double a[2], double qd[NDS_PANDA_NJ], double qdd[NDS_PANDA_NJ]) {
  const double fx = (p[0] - r->lo[0]) / r->step, fy = (p[1] - r->lo[1]) / r->step;
  if (!(fx >= 0.0 && fy >= 0.0 && fx <= r->nx - 1 && fy <= r->ny - 1)) return -1;
  int ix = (int)fx, iy = (int)fy;
  if (ix > r->nx - 2) ix = r->nx - 2;
  if (iy > r->ny - 2) iy = r->ny - 2;
  if (ix < 0) ix = 0;
  if (iy < 0) iy = 0;
  const double u = fx - ix, w = fy - iy;
  const int c = iy * r->nx + ix, nx = r->nx > 1 ? 1 : 0, ny = r->ny > 1 ? r->nx : 0;
  const int K = 2 * NDS_PANDA_NJ;
  const float *c00 = r->rate + (size_t)K * c, *c10 = r->rate + (size_t)K * (c + nx),
              *c01 = r->rate + (size_t)K * (c + ny), *c11 = r->rate + (size_t)K * (c + ny + nx);
  const float *s00 = r->slope + (size_t)2 * K * c, *s10 = r->slope + (size_t)2 * K * (c + nx),
              *s01 = r->slope + (size_t)2 * K * (c + ny),
              *s11 = r->slope + (size_t)2 * K * (c + ny + nx);
  /* Bilinear in the rates and in their slopes; an unreachable corner makes the whole cell
   * unreachable. The rates change along the path, so moving at v adds (dm/dp v) v to m a:
   * the joints' velocity-product terms. */
  for (int i = 0; i < NDS_PANDA_NJ; i++) {
    double m[2], g[2][2];
    for (int k = 0; k < 2; k++) {
      const int j = 2 * i + k;
      m[k] = (1 - w) * ((1 - u) * c00[j] + u * c10[j]) + w * ((1 - u) * c01[j] + u * c11[j]);
      for (int l = 0; l < 2; l++) {
        const int e = 2 * j + l;
        g[k][l] = (1 - w) * ((1 - u) * s00[e] + u * s10[e]) + w * ((1 - u) * s01[e] + u * s11[e]);
      }
    }
    if (!isfinite(m[0]) || !isfinite(m[1]) || !nd_all_finite(&g[0][0], 4)) return -1;
    qd[i] = m[0] * v[0] + m[1] * v[1];
    qdd[i] = m[0] * a[0] + m[1] * a[1];
    for (int k = 0; k < 2; k++) qdd[i] += (g[k][0] * v[0] + g[k][1] * v[1]) * v[k];
  }
  return 0;
}

double nds_reach_load(const nds_reach *r, const double p[2], const double v[2],
                      const double a[2]) {
  double qd[NDS_PANDA_NJ], qdd[NDS_PANDA_NJ];
  if (nds_reach_joint(r, p, v, a, qd, qdd)) return INFINITY;
  double load = 0.0;
  for (int i = 0; i < NDS_PANDA_NJ; i++) {
    const double lv = fabs(qd[i]) / nds_panda_dq_max[i], la = fabs(qdd[i]) / nds_panda_ddq_max[i];
    if (lv > load) load = lv;
    if (la > load) load = la;
  }
  return load;
}
