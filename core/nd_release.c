/* nd_release: the sphere's rest point after a task (nd_release.h). */
#include "nd_release.h"

#include <math.h>

#include "nd_math.h"

double nd_release_gap(const nd_release_box *b, double r, const double ee[2], double n[2]) {
  const double c = cos(b->yaw), s = sin(b->yaw);
  const double wd[2] = {ee[0] - b->x, ee[1] - b->y};
  /* The sphere's centre in the box's frame, and the box's nearest point to it. */
  double d[2];
  nd_rot2(c, -s, wd, d);
  const double q[2] = {nd_clamp(d[0], -b->half[0], b->half[0]),
                       nd_clamp(d[1], -b->half[1], b->half[1])};
  double u[2], dist;
  if (q[0] == d[0] && q[1] == d[1]) {
    /* Inside: out through the side with the least depth, the surface counted as -depth. */
    const double dx = b->half[0] - fabs(d[0]), dy = b->half[1] - fabs(d[1]);
    const int ax = dx <= dy ? 0 : 1;
    u[0] = ax == 0 ? (d[0] < 0 ? -1.0 : 1.0) : 0.0;
    u[1] = ax == 1 ? (d[1] < 0 ? -1.0 : 1.0) : 0.0;
    dist = -(ax == 0 ? dx : dy);
  } else {
    dist = nd_dist2(d, q);
    u[0] = (d[0] - q[0]) / dist;
    u[1] = (d[1] - q[1]) / dist;
  }
  nd_rot2(c, s, u, n);
  return dist - r;
}

double nd_release_target(const nd_release_box *b, double r, double clear, const double ee[2],
                         const double lo[2], const double hi[2], double out[2]) {
  double n[2];
  const double move = fmax(0.0, clear - nd_release_gap(b, r, ee, n));
  out[0] = nd_clamp(ee[0] + move * n[0], lo[0], hi[0]);
  out[1] = nd_clamp(ee[1] + move * n[1], lo[1], hi[1]);
  return nd_dist2(out, ee);
}
