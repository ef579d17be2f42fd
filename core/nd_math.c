/* nd_math: vector, angle and quaternion helpers. */
#include "nd_math.h"

#include <math.h>

double nd_wrap_angle(double a) {
  /* In-range angles come back bit-exact; fmod keeps large inputs accurate. */
  if (a >= -ND_PI && a < ND_PI) return a;
  double r = fmod(a + ND_PI, 2.0 * ND_PI);
  if (r < 0.0) r += 2.0 * ND_PI;
  r -= ND_PI;
  /* Rounding in the two additions can land exactly on +pi. */
  if (r >= ND_PI) r -= 2.0 * ND_PI;
  return r;
}

double nd_quat_yaw(const double q[4]) {
  /* Heading of the rotated body x-axis; the w^2 + x^2 - y^2 - z^2 form of R00 keeps
   * the result right for slightly unnormalised quaternions. */
  double w = q[0], x = q[1], y = q[2], z = q[3];
  return atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z);
}

void nd_quat_nlerp(const double a[4], const double b[4], double f, double q[4]) {
  const double s = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] < 0 ? -f : f;
  double n = 0;
  for (int i = 0; i < 4; i++) {
    q[i] = (1 - f) * a[i] + s * b[i];
    n += q[i] * q[i];
  }
  n = sqrt(n);
  for (int i = 0; i < 4; i++) q[i] /= n;
}

void nd_yaw_quat(double yaw, double q[4]) {
  q[0] = cos(0.5 * yaw);
  q[1] = 0.0;
  q[2] = 0.0;
  q[3] = sin(0.5 * yaw);
}

double nd_norm2_sq(const double v[2]) { return v[0] * v[0] + v[1] * v[1]; }

double nd_norm2(const double v[2]) { return hypot(v[0], v[1]); }

double nd_dist2(const double a[2], const double b[2]) { return hypot(a[0] - b[0], a[1] - b[1]); }

void nd_rot2(double c, double s, const double v[2], double out[2]) {
  const double x = c * v[0] - s * v[1], y = s * v[0] + c * v[1];
  out[0] = x;
  out[1] = y;
}

double nd_clamp(double x, double lo, double hi) {
  /* NaN falls through both comparisons and stays NaN, so callers can still detect it. */
  if (x < lo) return lo;
  if (x > hi) return hi;
  return x;
}

int nd_all_finite(const double *x, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(x[i])) return 0;
  return 1;
}
