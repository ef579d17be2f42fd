/* nd_exec: the executor's trajectory logic.
 *
 * Why the trajectory is "tracking segment, then a brake committed in advance": a
 * setpoint that coasts at constant velocity after a plan's segment ends would run the
 * robot into whatever lies ahead if the planner died, so every committed trajectory
 * ends at rest. A brake from the tracking segment's end state (v1, 0, 0) exists for any
 * |v1| < v_max (its speed falls monotonically from |v1|; it needs T >= 15/8 |v1| / a_max),
 * so that brake is computed when a plan is accepted, and a plan whose end cannot be
 * braked is refused up front.
 *
 * Going stale mid-segment is harder: a min-snap brake from a state with large
 * acceleration along the velocity (say 1.6 m/s and 13 m/s^2) overshoots v_max for every
 * duration, because the polynomial needs time to unwind the initial acceleration. So
 * the brake may depart from one of a few candidate times on the tracking segment; the
 * one reaching rest first wins, and the segment's end always qualifies.
 *
 * Limit checks are continuous-time: a quantity f sampled every h deviates from the
 * linear interpolation of its samples by at most h^2/8 max|f''|, and the norm of a
 * linear interpolant is at most its larger end. Chained from the 7th derivative (a
 * constant) down to the velocity, this bounds speed, acceleration and jerk everywhere
 * on [0, T], at a cost of a percent or two of conservatism with 64 samples.
 *
 * The workspace is enforced by refusing, not by clamping the setpoint. A min-snap segment
 * between keypoints inside the box can overshoot it (arriving fast, or turning), and a
 * brake from a keypoint moving outward travels 15/16 v^2 / a_max beyond it (7 cm at
 * 1 m/s). Clamping the position would cut p loose from v and a, which still carry the
 * motion: the setpoint would stop at the wall in one tick, a step the limits exist to
 * forbid, and the tracking controller would fight a command that contradicts itself. So
 * each piece is checked once, where it is built: its position range follows from the
 * same samples plus h^2/8 a_max between them (its acceleration is certified below a_max),
 * and a plan whose segment or brake leaves the box plus margin is refused like one that
 * breaks the limits: the committed trajectory goes on, and stale inputs bring it to rest
 * within the margin. The 1 kHz step pays nothing for it, except on going stale, when the
 * few brake candidates each get the same range check (doc/decisions.md#workspace). */
#include "nd_exec.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_math.h"

/* Geometric bisection steps between the last infeasible and the first feasible
 * duration: the result is within (hi/lo)^(1/64) of the boundary, 0.15% after a 1.1
 * stretch, 2.2% after the largest (4x) jump. */
#define ND_EXEC_BISECT 6
/* Brake departure candidates between now and the tracking segment's end. */
#define ND_EXEC_DEPART 4

nd_exec_cfg nd_exec_cfg_default(void) {
  nd_exec_cfg c;
  c.v_max = 1.7;
  c.a_max = 13.0;
  c.j_max = 6500.0;
  c.brake_a_max = 0.0;
  c.t_min = 0.01;
  c.t_max = 2.0;
  c.stretch = 1.1;
  c.n_check = 64;
  c.ws_lo[0] = c.ws_lo[1] = ND_EXEC_WS_LO;
  c.ws_hi[0] = c.ws_hi[1] = ND_EXEC_WS_HI;
  c.ws_margin = ND_EXEC_WS_MARGIN;
  return c;
}

static int pos_finite(double x) { return isfinite(x) && x > 0.0; }

double nd_exec_stale_brake_a(const nd_exec_cfg *cfg) {
  return cfg->brake_a_max > 0.0 ? fmin(cfg->a_max, cfg->brake_a_max) : cfg->a_max;
}

int nd_exec_cfg_check(const nd_exec_cfg *cfg, char *err, int errlen) {
  const char *msg = NULL;
  if (!pos_finite(cfg->v_max) || !pos_finite(cfg->a_max) || !pos_finite(cfg->j_max))
    msg = "limits v_max, a_max, j_max must be finite and positive";
  else if (!isfinite(cfg->brake_a_max) || cfg->brake_a_max < 0.0)
    msg = "brake_a_max must be finite and >= 0 (0: a_max)";
  else if (!pos_finite(cfg->t_min) || !isfinite(cfg->t_max) || cfg->t_max <= cfg->t_min)
    msg = "need 0 < t_min < t_max (finite)";
  else if (!isfinite(cfg->stretch) || cfg->stretch <= 1.0)
    msg = "stretch must be finite and > 1";
  else if (cfg->n_check < 2 || cfg->n_check > 100000)
    msg = "n_check must be in [2, 100000]";
  else if (!nd_all_finite(cfg->ws_lo, 2) || !nd_all_finite(cfg->ws_hi, 2) ||
           !(cfg->ws_lo[0] < cfg->ws_hi[0]) || !(cfg->ws_lo[1] < cfg->ws_hi[1]))
    msg = "the workspace needs finite bounds with lo < hi on x and y";
  else if (!isfinite(cfg->ws_margin) || cfg->ws_margin < 0.0)
    msg = "the workspace margin must be finite and >= 0";
  if (!msg) return ND_EXEC_OK;
  if (err && errlen > 0) snprintf(err, (size_t)errlen, "nd_exec: %s", msg);
  return ND_EXEC_EINVAL;
}

const char *nd_exec_mode_name(int mode) {
  switch (mode) {
    case ND_EXEC_TRACK: return "tracking";
    case ND_EXEC_STOPPING: return "stopping";
    case ND_EXEC_HOLD: return "holding";
    default: return "unknown";
  }
}

/* ---- limit bounds ---------------------------------------------------------------- */

/* Derivatives 1..5 of polynomial c at t into d[1..5] (d[0] unused). */
static void derivs15(const double dc[6][8], double t, double d[6]) {
  for (int k = 1; k <= 5; k++) {
    double s = 0.0;
    for (int n = 7 - k; n >= 0; n--) s = s * t + dc[k][n];
    d[k] = s;
  }
}

void nd_exec_seg_bounds(const nd_snap_seg *seg, int n, double max[3]) {
  /* dc[k][m]: coefficient of t^m in the k-th derivative, k = 1..5. */
  double dc[2][6][8];
  for (int ax = 0; ax < 2; ax++) {
    for (int m = 0; m < 8; m++) dc[ax][0][m] = seg->c[ax][m];
    for (int k = 1; k <= 5; k++)
      for (int m = 0; m < 8; m++)
        dc[ax][k][m] = m + 1 < 8 ? (double)(m + 1) * dc[ax][k - 1][m + 1] : 0.0;
  }
  const double T = seg->T;
  if (n < 2) n = 2;
  const double h = T / (double)n, w = h * h / 8.0;

  /* Norm maxima over the samples of derivatives 1..5. */
  double m[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  for (int i = 0; i <= n; i++) {
    const double t = i < n ? (double)i * h : T;
    double d0[6], d1[6];
    derivs15(dc[0], t, d0);
    derivs15(dc[1], t, d1);
    for (int k = 1; k <= 5; k++) {
      const double r = hypot(d0[k], d1[k]);
      if (r > m[k]) m[k] = r;
    }
  }
  /* 7th derivative: constant; 6th: linear, so its norm peaks at an end. */
  const double d7 = 5040.0 * hypot(seg->c[0][7], seg->c[1][7]);
  double d6a[2], d6b[2];
  for (int ax = 0; ax < 2; ax++) {
    d6a[ax] = 720.0 * seg->c[ax][6];
    d6b[ax] = 720.0 * seg->c[ax][6] + 5040.0 * seg->c[ax][7] * T;
  }
  const double d6 = fmax(hypot(d6a[0], d6a[1]), hypot(d6b[0], d6b[1]));

  const double b5 = m[5] + w * d7;
  const double b4 = m[4] + w * d6;
  const double b3 = m[3] + w * b5;
  const double b2 = m[2] + w * b4;
  const double b1 = m[1] + w * b3;
  max[0] = b1;
  max[1] = b2;
  max[2] = b3;
}

/* Fraction of the limits the segment uses: > 1 means infeasible. Also
 * the duration factor that would bring a rest-to-rest move within them (est). */
static double seg_load(const nd_exec_cfg *cfg, const nd_snap_seg *seg, double *est) {
  double b[3];
  nd_exec_seg_bounds(seg, cfg->n_check, b);
  const double rv = b[0] / cfg->v_max, ra = b[1] / cfg->a_max, rj = b[2] / cfg->j_max;
  if (est) *est = fmax(rv, fmax(sqrt(ra), cbrt(rj)));
  const double r = fmax(rv, fmax(ra, rj));
  return isfinite(r) ? r : INFINITY;
}

/* ---- workspace --------------------------------------------------------------------- */

/* Range of positions over [0, seg->T] per axis into lo[2], hi[2]: n samples widened by
 * the most a curve with |p''| <= a_bound can leave the chord between two of them. */
static void seg_range(const nd_snap_seg *seg, int n, double a_bound, double lo[2],
                      double hi[2]) {
  const double T = seg->T, h = T / (double)n, w = h * h / 8.0 * a_bound;
  for (int ax = 0; ax < 2; ax++) lo[ax] = INFINITY, hi[ax] = -INFINITY;
  for (int i = 0; i <= n; i++) {
    const double t = i < n ? (double)i * h : T;
    for (int ax = 0; ax < 2; ax++) {
      const double *c = seg->c[ax];
      double p = 0.0;
      for (int k = 7; k >= 0; k--) p = p * t + c[k];
      if (p < lo[ax]) lo[ax] = p;
      if (p > hi[ax]) hi[ax] = p;
    }
  }
  for (int ax = 0; ax < 2; ax++) lo[ax] -= w, hi[ax] += w;
}

/* How far (m) a committed piece (limits already certified) gets beyond the workspace plus
 * margin: <= 0 inside. *axis, *at: the worst axis and the position it reaches there. */
static double seg_outside(const nd_exec_cfg *cfg, const nd_snap_seg *seg, int *axis,
                          double *at) {
  double lo[2], hi[2], worst = -INFINITY;
  seg_range(seg, cfg->n_check, cfg->a_max, lo, hi);
  for (int ax = 0; ax < 2; ax++) {
    const double below = (cfg->ws_lo[ax] - cfg->ws_margin) - lo[ax];
    const double above = hi[ax] - (cfg->ws_hi[ax] + cfg->ws_margin);
    if (below > worst) worst = below, *axis = ax, *at = lo[ax];
    if (above > worst) worst = above, *axis = ax, *at = hi[ax];
  }
  return isfinite(worst) ? worst : INFINITY;
}

int nd_exec_keys_check(const nd_exec_cfg *cfg, const double (*keys)[4], int n, char *err,
                       int errlen) {
  for (int k = 0; k < n; k++) {
    const double x = keys[k][0], y = keys[k][1];
    if (x >= cfg->ws_lo[0] && x <= cfg->ws_hi[0] && y >= cfg->ws_lo[1] && y <= cfg->ws_hi[1])
      continue;
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: keypoint %d (%.3f, %.3f) is outside the "
               "workspace x [%.3f, %.3f], y [%.3f, %.3f] m", k, x, y, cfg->ws_lo[0],
               cfg->ws_hi[0], cfg->ws_lo[1], cfg->ws_hi[1]);
    return ND_EXEC_EBOX;
  }
  return ND_EXEC_OK;
}

/* ---- segment construction ---------------------------------------------------------- */

/* Inner product of the snaps of two polynomials over [0, T]. */
static double snap_dot(const double ca[8], const double cb[8], double T) {
  const double sa[4] = {24.0 * ca[4], 120.0 * ca[5], 360.0 * ca[6], 840.0 * ca[7]};
  const double sb[4] = {24.0 * cb[4], 120.0 * cb[5], 360.0 * cb[6], 840.0 * cb[7]};
  double Tp[8];
  Tp[0] = T;
  for (int k = 1; k < 8; k++) Tp[k] = Tp[k - 1] * T;
  double sum = 0.0;
  for (int i = 0; i < 4; i++)
    for (int j = 0; j < 4; j++) sum += sa[i] * sb[j] * Tp[i + j] / (double)(i + j + 1);
  return sum;
}

/* Brake of duration T from s0 to rest at the position that minimises the snap integral
 * (free end). From (p, v, 0, 0) that position is p + v T / 2 and the speed falls
 * monotonically; from other states it accounts for the initial acceleration and jerk. */
static void brake_make(nd_snap_seg *seg, const double s0[2][4], double T) {
  static const double zero[4] = {0.0, 0.0, 0.0, 0.0};
  double unit[8];
  nd_snap_coeffs(zero, 1.0, 0.0, T, unit);
  const double uu = snap_dot(unit, unit, T);
  seg->T = T;
  for (int ax = 0; ax < 2; ax++) {
    const double base = s0[ax][ND_P] + 0.5 * s0[ax][ND_V] * T;
    double *c = seg->c[ax];
    nd_snap_coeffs(s0[ax], base, 0.0, T, c);
    const double delta = -snap_dot(c, unit, T) / uu;
    for (int k = 0; k < 8; k++) c[k] += delta * unit[k];
  }
}

/* Tracking segment to (p1, v1), or with p1 NULL a brake to rest. */
static void make(nd_snap_seg *seg, const double s0[2][4], const double *p1,
                 const double *v1, double T) {
  if (p1)
    nd_snap_seg_make(seg, s0, p1, v1, T);
  else
    brake_make(seg, s0, T);
}

/* Shortest duration from T0 (stretching, then bisecting) at which make() gives a
 * segment within the limits; 0 with *seg a feasible segment, or -1. Feasibility need
 * not be monotone in T (initial acceleration makes long brakes overshoot), so this is
 * the first feasible duration found, not necessarily the global shortest. */
static int fit(const nd_exec_cfg *cfg, const double s0[2][4], const double *p1,
               const double *v1, double T0, nd_snap_seg *seg) {
  double T = fmax(T0, cfg->t_min), lo = 0.0, est = 1.0;
  nd_snap_seg cand;
  for (;;) {
    make(&cand, s0, p1, v1, T);
    if (seg_load(cfg, &cand, &est) <= 1.0) break;
    if (T >= cfg->t_max) return -1;
    lo = T;
    /* est is exact for pure time-scaling; cap it so a bad guess cannot skip far. */
    T = fmin(T * fmax(cfg->stretch, fmin(est, 4.0)), cfg->t_max);
  }
  *seg = cand;
  if (lo > 0.0) {
    double hi = T;
    for (int i = 0; i < ND_EXEC_BISECT; i++) {
      const double mid = sqrt(lo * hi);
      make(&cand, s0, p1, v1, mid);
      if (seg_load(cfg, &cand, NULL) <= 1.0) {
        hi = mid;
        *seg = cand;
      } else {
        lo = mid;
      }
    }
  }
  return 0;
}

/* Brake from state s to rest into *seg, *hold the rest position; T = 0 when s is at
 * rest already. With capped set its acceleration keeps to brake_a_max where that is set:
 * a state already accelerating harder has no such brake. 0 or -1 (no duration up to
 * t_max fits the limits). */
static int brake_fit(const nd_exec_cfg *limits, int capped, const double s[2][4],
                     nd_snap_seg *seg, double hold[2]) {
  nd_exec_cfg braking = *limits;
  if (capped) braking.a_max = nd_exec_stale_brake_a(limits);
  const nd_exec_cfg *cfg = &braking;
  int moving = 0;
  for (int ax = 0; ax < 2; ax++)
    for (int k = ND_V; k <= ND_J; k++) moving |= s[ax][k] != 0.0;
  if (!moving) {
    memset(seg, 0, sizeof(*seg));
    for (int ax = 0; ax < 2; ax++) seg->c[ax][0] = hold[ax] = s[ax][ND_P];
    return 0;
  }
  /* Start at the duration a brake from (v, 0, 0) needs: peak |a| = 15/8 |v| / T,
   * peak |j| = (10 / sqrt 3) |v| / T^2 for the free-end min-snap stop. */
  const double v = hypot(s[0][ND_V], s[1][ND_V]);
  const double T0 = fmax(1.875 * v / cfg->a_max, sqrt(5.7735 * v / cfg->j_max));
  if (fit(cfg, s, NULL, NULL, T0, seg) != 0) return -1;
  double end[2][4];
  nd_snap_seg_eval(seg, seg->T, end);
  hold[0] = end[0][ND_P];
  hold[1] = end[1][ND_P];
  return 0;
}

/* ---- state ------------------------------------------------------------------------- */

void nd_exec_init(nd_exec *ex, const double p[2], double now) {
  memset(ex, 0, sizeof(*ex));
  ex->mode = ND_EXEC_HOLD;
  ex->t_last = now;
  ex->t_seg = ex->t_brake = now;
  for (int ax = 0; ax < 2; ax++) {
    ex->hold[ax] = ex->sp[ax][ND_P] = p[ax];
    ex->seg.c[ax][0] = ex->brake.c[ax][0] = p[ax];
  }
}

void nd_exec_eval(const nd_exec *ex, double t, double out[2][4]) {
  if (ex->mode != ND_EXEC_HOLD) {
    if (t < ex->t_brake) {
      nd_snap_seg_eval(&ex->seg, t - ex->t_seg, out);
      return;
    }
    if (t < ex->t_brake + ex->brake.T) {
      nd_snap_seg_eval(&ex->brake, t - ex->t_brake, out);
      return;
    }
  }
  for (int ax = 0; ax < 2; ax++) {
    out[ax][ND_P] = ex->hold[ax];
    out[ax][ND_V] = out[ax][ND_A] = out[ax][ND_J] = 0.0;
  }
}

int nd_exec_plan(nd_exec *ex, const nd_exec_cfg *cfg, double now, const double key[4],
                 double T, char *err, int errlen) {
  if (!isfinite(now) || !isfinite(T) || !nd_all_finite(key, 4)) {
    if (err && errlen > 0) snprintf(err, (size_t)errlen, "nd_exec: plan has a non-finite "
                                    "keypoint, duration or time");
    return ND_EXEC_EINVAL;
  }
  if (T <= 0.0) {
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: segment duration %g s is not positive", T);
    return ND_EXEC_EINVAL;
  }
  const double vk = hypot(key[2], key[3]);
  if (vk > cfg->v_max) {
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: keypoint speed %.3f m/s exceeds v_max %.3f",
               vk, cfg->v_max);
    return ND_EXEC_ELIMIT;
  }
  if (nd_exec_keys_check(cfg, (const double(*)[4])key, 1, err, errlen) != ND_EXEC_OK)
    return ND_EXEC_EBOX;
  if (now < ex->t_last) now = ex->t_last;

  const double p1[2] = {key[0], key[1]}, v1[2] = {key[2], key[3]};
  double s0[2][4], end[2][4], hold[2];
  nd_snap_seg seg, brake;
  /* The brake from the keypoint itself first: it is cheap, and it is what fails for a
   * speed at v_max, which the tracking search would misreport as unreachable. */
  const double ideal[2][4] = {{key[0], key[2], 0.0, 0.0}, {key[1], key[3], 0.0, 0.0}};
  if (brake_fit(cfg, 0, ideal, &brake, hold) != 0) {
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: keypoint speed %.4f m/s too close to v_max "
               "%.3f to certify a brake", vk, cfg->v_max);
    return ND_EXEC_ELIMIT;
  }
  nd_exec_eval(ex, now, s0);
  if (fit(cfg, s0, p1, v1, T, &seg) != 0) {
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: keypoint (%.3f, %.3f) not reachable within "
               "the limits in %g s or less", key[0], key[1], cfg->t_max);
    return ND_EXEC_ELIMIT;
  }
  nd_snap_seg_eval(&seg, seg.T, end);
  if (brake_fit(cfg, 0, end, &brake, hold) != 0) {
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: no brake to rest from the keypoint within "
               "the limits");
    return ND_EXEC_ELIMIT;
  }
  int axis = 0;
  double at = 0.0;
  const nd_snap_seg *piece[2] = {&seg, &brake};
  for (int i = 0; i < 2; i++) {
    if (!(seg_outside(cfg, piece[i], &axis, &at) > 0.0)) continue;
    if (err && errlen > 0)
      snprintf(err, (size_t)errlen, "nd_exec: the %s to keypoint (%.3f, %.3f) reaches %c = "
               "%.3f m, beyond the workspace [%.3f, %.3f] m plus its %.3f m margin",
               i ? "brake after the segment" : "segment", key[0], key[1], "xy"[axis], at,
               cfg->ws_lo[axis], cfg->ws_hi[axis], cfg->ws_margin);
    return ND_EXEC_EBOX;
  }
  ex->mode = ND_EXEC_TRACK;
  ex->t_last = now;
  ex->seg = seg;
  ex->t_seg = now;
  ex->brake = brake;
  ex->t_brake = now + seg.T;
  ex->hold[0] = hold[0];
  ex->hold[1] = hold[1];
  return ND_EXEC_OK;
}

int nd_exec_heading_to(const nd_exec *ex, double now, const double key[4], double tol) {
  if (ex->mode != ND_EXEC_TRACK || !(now < ex->t_brake)) return 0;
  double end[2][4];
  nd_snap_seg_eval(&ex->seg, ex->seg.T, end);
  for (int ax = 0; ax < 2; ax++)
    if (!(fabs(end[ax][0] - key[ax]) <= tol) || !(fabs(end[ax][1] - key[2 + ax]) <= tol))
      return 0;
  return 1;
}

/* Commit to rest from time t on the tracking segment: of a few candidate departures
 * from t to the segment's end, each braking within brake_a_max, take the one that reaches
 * rest first and stays within the workspace margin; if none does, the brake planned with
 * the segment (at a_max, always feasible and inside the margin). Reaching rest first, not
 * departing first, is what keeps a robot with stale inputs safe; an early brake toward
 * the wall at speed would stop beyond where the planned one does. The cap holds here and
 * not in the planned brake: only this brake runs when plans stop mid-segment, and a
 * planned brake at the cap would travel further and shrink the workspace plans may use. */
static void begin_stop(nd_exec *ex, const nd_exec_cfg *cfg, double t) {
  const double t_end = ex->t_brake;
  double best = INFINITY;
  for (int k = 0; k <= ND_EXEC_DEPART; k++) {
    const double td = t + (t_end - t) * (double)k / ND_EXEC_DEPART;
    double s[2][4], hold[2];
    nd_snap_seg brake;
    if (td >= best) break;
    nd_snap_seg_eval(&ex->seg, td - ex->t_seg, s);
    int axis;
    double at;
    if (brake_fit(cfg, 1, s, &brake, hold) == 0 && td + brake.T < best &&
        !(seg_outside(cfg, &brake, &axis, &at) > 0.0)) {
      best = td + brake.T;
      ex->brake = brake;
      ex->t_brake = td;
      ex->hold[0] = hold[0];
      ex->hold[1] = hold[1];
    }
  }
  ex->mode = ND_EXEC_STOPPING;
}

int nd_exec_step(nd_exec *ex, const nd_exec_cfg *cfg, double now, int stale,
                 double out[2][4]) {
  const double t = isfinite(now) && now > ex->t_last ? now : ex->t_last;
  if (stale && ex->mode == ND_EXEC_TRACK && t < ex->t_brake) begin_stop(ex, cfg, t);
  if (ex->mode == ND_EXEC_TRACK && t >= ex->t_brake) ex->mode = ND_EXEC_STOPPING;
  if (ex->mode == ND_EXEC_STOPPING && t >= ex->t_brake + ex->brake.T) ex->mode = ND_EXEC_HOLD;
  nd_exec_eval(ex, t, out);
  memcpy(ex->sp, out, sizeof(ex->sp));
  ex->t_last = t;
  return ex->mode;
}

/* ---- the future, for receivers ------------------------------------------------------- */

void nd_exec_future_get(const nd_exec *ex, nd_exec_future *f) {
  double end[2][4];
  if (ex->mode == ND_EXEC_HOLD) {
    f->t_seg_end = f->t_brake = f->t_rest = ex->t_last;
    for (int ax = 0; ax < 2; ax++) f->key[ax] = f->hold[ax] = ex->hold[ax], f->key[2 + ax] = 0.0;
    return;
  }
  f->t_seg_end = ex->t_seg + ex->seg.T;
  nd_snap_seg_eval(&ex->seg, ex->seg.T, end);
  for (int ax = 0; ax < 2; ax++) f->key[ax] = end[ax][ND_P], f->key[2 + ax] = end[ax][ND_V];
  f->t_brake = ex->t_brake;
  f->t_rest = ex->t_brake + ex->brake.T;
  f->hold[0] = ex->hold[0];
  f->hold[1] = ex->hold[1];
}

/* Rebuild the piece that runs from state s at t to (p1, v1, 0, 0) at t_end, into s at t1
 * <= t_end; a piece with less than ND_EXEC_REBUILD_MIN left is taken as ended. */
static void rebuild(double s[2][4], double t, const double p1[2], const double v1[2],
                    double t_end, double t1) {
  if (t_end - t < ND_EXEC_REBUILD_MIN) {
    for (int ax = 0; ax < 2; ax++) s[ax][ND_P] = p1[ax], s[ax][ND_V] = v1[ax];
    for (int ax = 0; ax < 2; ax++) s[ax][ND_A] = s[ax][ND_J] = 0.0;
    /* From an ended piece the state moves on at its end velocity, as the executor's
     * segment evaluation does past its end (v1 is zero for a brake). */
    for (int ax = 0; ax < 2; ax++) s[ax][ND_P] += v1[ax] * (t1 - t_end);
    return;
  }
  nd_snap_seg seg;
  nd_snap_seg_make(&seg, (const double(*)[4])s, p1, v1, t_end - t);
  nd_snap_seg_eval(&seg, t1 - t, s);
}

void nd_exec_future_eval(const double sp[2][4], double t, const nd_exec_future *f, double t1,
                         double out[2][4]) {
  static const double zero[2] = {0.0, 0.0};
  double s[2][4];
  memcpy(s, sp, sizeof(s));
  if (t1 < t) t1 = t;
  if (t < f->t_brake) {
    /* On the tracking segment: to its end, or to the brake's departure if sooner. */
    const double te = fmin(f->t_brake, t1);
    rebuild(s, t, f->key, f->key + 2, f->t_seg_end, te);
    t = te;
  }
  if (t1 > t && t < f->t_rest) {
    const double te = fmin(f->t_rest, t1);
    rebuild(s, t, f->hold, zero, f->t_rest, te);
    t = te;
  }
  if (t1 > t) {
    for (int ax = 0; ax < 2; ax++) s[ax][ND_P] = f->hold[ax];
    for (int ax = 0; ax < 2; ax++) s[ax][ND_V] = s[ax][ND_A] = s[ax][ND_J] = 0.0;
  }
  memcpy(out, s, sizeof(s));
}

