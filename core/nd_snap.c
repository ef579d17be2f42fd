/* nd_snap: closed-form minimum-snap segments.
 *
 * The start state fixes c0..c3 directly. For the rest, write d_k = c_k T^k (k = 4..7):
 * the four end conditions become a fixed 4x4 system in d whose matrix does not depend
 * on T,
 *     [ 1  1   1   1 ]       [ dp       ]
 *     [ 4  5   6   7 ] d  =  [ dv T     ]
 *     [12 20  30  42 ]       [ da T^2   ]
 *     [24 60 120 210 ]       [ dj T^3   ]
 * where dp, dv, da, dj are what the cubic part c0..c3 leaves missing at T. Its exact
 * rational inverse is applied below, so the solve is well conditioned for any T.
 * A 7th-degree polynomial is the minimum-snap solution because the Euler-Lagrange
 * equation of the integral of squared snap is p^(8) = 0. */
#include "nd_snap.h"

#include <string.h>

void nd_snap_coeffs(const double s0[4], double p1, double v1, double T, double c[8]) {
  c[0] = s0[ND_P];
  c[1] = s0[ND_V];
  c[2] = 0.5 * s0[ND_A];
  c[3] = s0[ND_J] / 6.0;

  const double T2 = T * T, T3 = T2 * T;
  const double dp = p1 - (c[0] + T * (c[1] + T * (c[2] + T * c[3])));
  const double dv = (v1 - (c[1] + T * (2.0 * c[2] + 3.0 * T * c[3]))) * T;
  const double da = -(2.0 * c[2] + 6.0 * T * c[3]) * T2;
  const double dj = -6.0 * c[3] * T3;

  const double d4 = 35.0 * dp - 15.0 * dv + 2.5 * da - dj / 6.0;
  const double d5 = -84.0 * dp + 39.0 * dv - 7.0 * da + 0.5 * dj;
  const double d6 = 70.0 * dp - 34.0 * dv + 6.5 * da - 0.5 * dj;
  const double d7 = -20.0 * dp + 10.0 * dv - 2.0 * da + dj / 6.0;

  const double T4 = T2 * T2;
  c[4] = d4 / T4;
  c[5] = d5 / (T4 * T);
  c[6] = d6 / (T4 * T2);
  c[7] = d7 / (T4 * T3);
}

void nd_snap_eval_poly(const double c[8], double t, double out[4]) {
  double p = c[7], v = 7.0 * c[7], a = 42.0 * c[7], j = 210.0 * c[7];
  p = p * t + c[6];
  v = v * t + 6.0 * c[6];
  a = a * t + 30.0 * c[6];
  j = j * t + 120.0 * c[6];
  p = p * t + c[5];
  v = v * t + 5.0 * c[5];
  a = a * t + 20.0 * c[5];
  j = j * t + 60.0 * c[5];
  p = p * t + c[4];
  v = v * t + 4.0 * c[4];
  a = a * t + 12.0 * c[4];
  j = j * t + 24.0 * c[4];
  p = p * t + c[3];
  v = v * t + 3.0 * c[3];
  a = a * t + 6.0 * c[3];
  j = j * t + 6.0 * c[3];
  p = p * t + c[2];
  v = v * t + 2.0 * c[2];
  a = a * t + 2.0 * c[2];
  p = p * t + c[1];
  v = v * t + c[1];
  p = p * t + c[0];
  out[ND_P] = p;
  out[ND_V] = v;
  out[ND_A] = a;
  out[ND_J] = j;
}

double nd_snap_cost(const double c[8], double T) {
  /* Snap is the cubic s(t) = sum_i b_i t^i; integrate s^2 term by term. */
  const double b[4] = {24.0 * c[4], 120.0 * c[5], 360.0 * c[6], 840.0 * c[7]};
  double Tp[8];
  Tp[0] = T;
  for (int k = 1; k < 8; k++) Tp[k] = Tp[k - 1] * T;
  double sum = 0.0;
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) sum += b[i] * b[j] * Tp[i + j] / (double)(i + j + 1);
  return sum;
}

void nd_snap_seg_make(nd_snap_seg *seg, const double s0[2][4], const double p1[2],
                      const double v1[2], double T) {
  seg->T = T;
  for (int ax = 0; ax < 2; ax++) nd_snap_coeffs(s0[ax], p1[ax], v1[ax], T, seg->c[ax]);
}

void nd_snap_seg_eval(const nd_snap_seg *seg, double t, double out[2][4]) {
  if (t < 0.0) t = 0.0;
  const double tc = t < seg->T ? t : seg->T;
  for (int ax = 0; ax < 2; ax++) {
    nd_snap_eval_poly(seg->c[ax], tc, out[ax]);
    if (t > seg->T) {
      /* Past the end: coast at the end velocity, which is what the end conditions
       * (zero acceleration and jerk) make the natural continuation. */
      out[ax][ND_P] += out[ax][ND_V] * (t - seg->T);
      out[ax][ND_A] = 0.0;
      out[ax][ND_J] = 0.0;
    }
  }
}

void nd_snap_chain(nd_snap_seg *seg, const double s0[2][4], const double *keys, int M, double T) {
  double s[2][4];
  memcpy(s, s0, sizeof(s));
  for (int i = 0; i < M; i++) {
    nd_snap_seg_make(&seg[i], (const double(*)[4])s, keys + 4 * i, keys + 4 * i + 2, T);
    nd_snap_seg_eval(&seg[i], T, s);
  }
}

void nd_snap_retime(const double s0[2][4], const double *keys, int M, double T, double dt,
                    double *out) {
  nd_snap_seg seg[ND_MAX_KEYS];
  double s[2][4], r[ND_MAX_KEYS][4];
  nd_snap_chain(seg, s0, keys, M, T);
  for (int k = 0; k < M; k++) {
    const double tau = dt + (k + 1) * T;
    /* The last keypoint is the end state itself: take it as given, not re-evaluated. */
    const int i = tau < M * T ? (int)(tau / T) : M;
    if (i >= M) {
      memcpy(r[k], keys + 4 * (M - 1), sizeof(r[k]));
      continue;
    }
    nd_snap_seg_eval(&seg[i], tau - i * T, s);
    r[k][0] = s[0][ND_P], r[k][1] = s[1][ND_P];
    r[k][2] = s[0][ND_V], r[k][3] = s[1][ND_V];
  }
  memcpy(out, r, sizeof(double) * 4 * (size_t)M);
}
