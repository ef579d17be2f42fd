/* nd_objest: box-filter differences of mocap poses, clamped. */
#include "nd_objest.h"

#include <math.h>
#include <string.h>

#include "nd_math.h"

void nd_objest_cfg_default(nd_objest_cfg *cfg, double v_max, double w_max) {
  cfg->window = 0.025;
  cfg->max_gap = 0.1;
  cfg->v_max = v_max;
  cfg->w_max = w_max;
}

void nd_objest_init(nd_objest *e, const nd_objest_cfg *cfg) {
  memset(e, 0, sizeof(*e));
  e->cfg = *cfg;
}

void nd_objest_reset(nd_objest *e) { e->head = e->n = 0; }

void nd_objest_add(nd_objest *e, int64_t utime, const double pos[3], const double quat[4]) {
  if (e->n && utime <= e->hist[(e->head + ND_OBJEST_HIST - 1) % ND_OBJEST_HIST].utime)
    nd_objest_reset(e);
  nd_objest_frame *f = &e->hist[e->head];
  f->utime = utime;
  f->x = pos[0];
  f->y = pos[1];
  f->yaw = nd_quat_yaw(quat);
  memcpy(f->quat, quat, sizeof(f->quat));
  e->head = (e->head + 1) % ND_OBJEST_HIST;
  if (e->n < ND_OBJEST_HIST) e->n++;
}

void nd_objest_velocity(const nd_objest *e, double v[6]) {
  memset(v, 0, 6 * sizeof(double));
  if (e->n < 2) return;
  const nd_objest_frame *cur = &e->hist[(e->head + ND_OBJEST_HIST - 1) % ND_OBJEST_HIST];
  const nd_objest_frame *old = NULL;
  for (int k = 2; k <= e->n; k++) {
    old = &e->hist[(e->head + ND_OBJEST_HIST - k) % ND_OBJEST_HIST];
    if (1e-6 * (double)(cur->utime - old->utime) >= e->cfg.window) break;
  }
  const double dt = 1e-6 * (double)(cur->utime - old->utime);
  if (!(dt > 0.0) || dt > e->cfg.max_gap) return;

  double vx = (cur->x - old->x) / dt, vy = (cur->y - old->y) / dt;
  const double speed = hypot(vx, vy);
  if (speed > e->cfg.v_max) vx *= e->cfg.v_max / speed, vy *= e->cfg.v_max / speed;
  const double wz =
      nd_clamp(nd_wrap_angle(cur->yaw - old->yaw) / dt, -e->cfg.w_max, e->cfg.w_max);

  /* The world yaw rate (0, 0, wz) in the body frame is R^T e_z wz: the third row of the
   * rotation matrix of the (normalised) orientation. */
  const double *q = cur->quat;
  const double nq = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  const double w = q[0] / nq, x = q[1] / nq, y = q[2] / nq, z = q[3] / nq;
  v[0] = vx;
  v[1] = vy;
  v[3] = 2 * (x * z - w * y) * wz;
  v[4] = 2 * (y * z + w * x) * wz;
  v[5] = (1 - 2 * (x * x + y * y)) * wz;
}
