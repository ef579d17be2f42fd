/* nd_snap: closed-form minimum-snap segments (7th-degree polynomials).
 *
 * One axis: p(t) = sum_k c[k] t^k on [0, T] with p, p', p'', p''' at t=0 given and
 * p(T) = p1, p'(T) = v1, p''(T) = 0, p'''(T) = 0. Eight conditions fix the eight
 * coefficients; the resulting polynomial minimises the integral of squared snap. */
#ifndef ND_SNAP_H
#define ND_SNAP_H

/* Most keypoints (one min-snap segment each) a plan may carry: plan_t's MAX_KEYPOINTS,
 * checked where the two meet (processes/common/ndp_validate.h). */
#define ND_MAX_KEYS 8

/* Kinematic state of one axis: position, velocity, acceleration, jerk. */
enum { ND_P = 0, ND_V = 1, ND_A = 2, ND_J = 3 };

/* Coefficients of one axis from start state s0 = (p, v, a, j) to (p1, v1, 0, 0) at T > 0. */
void nd_snap_coeffs(const double s0[4], double p1, double v1, double T, double c[8]);

/* Evaluate (p, v, a, j) of coefficients c at time t (no clamping). */
void nd_snap_eval_poly(const double c[8], double t, double out[4]);

/* Integral of squared snap of coefficients c over [0, T] (exact). */
double nd_snap_cost(const double c[8], double T);

/* A planar segment: two axes (x, y) sharing one duration. */
typedef struct {
  double T;         /* duration, seconds */
  double c[2][8];   /* coefficients per axis */
} nd_snap_seg;

/* Build a planar segment from start state s0[axis][p,v,a,j] to position p1 and
 * velocity v1 (both [x, y]) with zero acceleration and jerk at T > 0. */
void nd_snap_seg_make(nd_snap_seg *seg, const double s0[2][4], const double p1[2],
                      const double v1[2], double T);

/* State out[axis][p,v,a,j] at time t. For t > T the segment continues at its end
 * velocity (p1 + v1 (t - T), v1, 0, 0); for t < 0 it evaluates at 0. */
void nd_snap_seg_eval(const nd_snap_seg *seg, double t, double out[2][4]);

/* M segments of T chained from s0 through keys[k] = (x, y, vx, vy) into seg[0..M): each
 * starts where the one before ends, so the chain is C3-continuous. */
void nd_snap_chain(nd_snap_seg *seg, const double s0[2][4], const double *keys, int M, double T);

/* The chain of M segments of T from s0 through keys[k] = (x, y, vx, vy), sampled T apart
 * from dt >= 0 on: out[k] = (x, y, vx, vy) at dt + (k + 1) T, or keys[M - 1] past the
 * chain's end. out may be keys. A re-plan dt later goes on along the same path with it. */
void nd_snap_retime(const double s0[2][4], const double *keys, int M, double T, double dt,
                    double *out);

#endif
