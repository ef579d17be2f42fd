/* nd_math: the few vector, angle and quaternion helpers the system needs. */
#ifndef ND_MATH_H
#define ND_MATH_H

#define ND_PI 3.14159265358979323846

/* Wrap an angle to [-pi, pi). */
double nd_wrap_angle(double a);

/* Yaw (rotation about world z) of a w-first unit quaternion (w, x, y, z). */
double nd_quat_yaw(const double q[4]);

/* W-first quaternion of a pure rotation by yaw about world z. */
void nd_yaw_quat(double yaw, double q[4]);

/* Unit quaternion a fraction f in [0, 1] of the way from unit quaternion a to b, along the
 * shorter arc (b and -b are one rotation): normalised linear interpolation, which between
 * two mocap frames a few milliseconds apart is slerp to ~1e-7 rad. */
void nd_quat_nlerp(const double a[4], const double b[4], double f, double q[4]);

/* Squared and plain Euclidean norm of a 2-vector; distance between two 2-points. */
double nd_norm2_sq(const double v[2]);
double nd_norm2(const double v[2]);
double nd_dist2(const double a[2], const double b[2]);

/* Turn the 2-vector v by the angle of cosine c and sine s into out (out may be v): (c, s)
 * takes a body frame's coordinates to the world's, (c, -s) the world's to the body's. */
void nd_rot2(double c, double s, const double v[2], double out[2]);

/* Clamp x to [lo, hi]. */
double nd_clamp(double x, double lo, double hi);

/* 1 if all n values are finite, else 0. */
int nd_all_finite(const double *x, int n);

#endif
