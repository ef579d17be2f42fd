/* nd_recorder: samples in, one rollout out. */
#include "nd_recorder.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"

int nd_recorder_init(nd_recorder *rc, double tau, double dt, char *err, int errlen) {
  memset(rc, 0, sizeof(*rc));
  rc->dt = dt;
  /* Room for a task that overruns its limit a little (runners check it at 50 Hz) and for a
   * robot somewhat faster than dt says; what does not fit is cut off. */
  const double n = ceil(1.25 * tau / dt) + 1000;
  rc->cap = n > ND_ROLLOUT_MAX_STEPS ? ND_ROLLOUT_MAX_STEPS : (int)n;
  rc->step_us = malloc(sizeof(int64_t) * rc->cap);
  rc->frame_us = malloc(sizeof(int64_t) * rc->cap);
  rc->frame = malloc(sizeof(double) * ND_ROLLOUT_OBJ * rc->cap);
  if (nd_rollout_alloc(&rc->r, rc->cap) || !rc->step_us || !rc->frame_us || !rc->frame) {
    snprintf(err, errlen, "out of memory for %d recorded steps", rc->cap);
    nd_recorder_free(rc);
    return -1;
  }
  return 0;
}

void nd_recorder_free(nd_recorder *rc) {
  nd_rollout_free(&rc->r);
  free(rc->step_us);
  free(rc->frame_us);
  free(rc->frame);
  rc->step_us = rc->frame_us = NULL;
  rc->frame = NULL;
}

void nd_recorder_frame(nd_recorder *rc, int64_t utime, const double pose[ND_ROLLOUT_OBJ]) {
  if (!rc->on || rc->nframes >= rc->cap) return;
  if (rc->nframes > 0 && utime <= rc->frame_us[rc->nframes - 1]) return;
  rc->frame_us[rc->nframes] = utime;
  memcpy(rc->frame + ND_ROLLOUT_OBJ * rc->nframes, pose, ND_ROLLOUT_OBJ * sizeof(double));
  rc->nframes++;
}

void nd_recorder_begin(nd_recorder *rc, const nd_rec_state *s, int64_t frame_us,
                       const double pose[ND_ROLLOUT_OBJ], int64_t id, const double goal[3],
                       const double theta[ND_NTHETA], int control) {
  nd_rollout *r = &rc->r;
  rc->on = 1;
  rc->steps = rc->nframes = rc->dropped = 0;
  rc->filled = rc->longest_gap = 0;
  rc->broken[0] = '\0';
  r->n = rc->cap;
  if (!s) {
    snprintf(rc->broken, sizeof(rc->broken),
             "no robot state received before the task: is the robot (nudge-bridge) publishing?");
    return;
  }
  r->task_id = id;
  r->utime = s->utime;
  memcpy(r->goal, goal, sizeof(r->goal));
  memcpy(r->theta, theta, sizeof(r->theta));
  r->outcome = ND_OUTCOME_ABORTED;
  r->control = control;
  r->dt = rc->dt;
  memcpy(r->obj_pos, pose, sizeof(r->obj_pos));
  memcpy(r->obj_quat, pose + 3, sizeof(r->obj_quat));
  memset(r->obj_vel, 0, sizeof(r->obj_vel));  /* at rest after the settle pause */
  for (int k = 0; k < 2; k++) {
    r->ee_pos[k] = s->ee_pos[k];
    r->ee_vel[k] = s->ee_vel[k];
    rc->last_u[k] = control == ND_CTRL_VELOCITY ? s->ee_vel[k] : s->force[k];
    rc->last_ee[k] = s->ee_pos[k];
  }
  rc->last_seq = s->seq;
  rc->last_us = rc->start_us = s->utime;
  nd_recorder_frame(rc, frame_us, pose);
}

void nd_recorder_setpoint(nd_recorder *rc, const nd_rec_setpoint *sp) {
  rc->sp = *sp;
  rc->have_sp = 1;
}

/* One step: control u during it, sphere ee after it, at utime us. */
static void push(nd_recorder *rc, const double u[2], const double ee[2], int64_t us) {
  if (rc->steps >= rc->cap) {
    rc->dropped++;
    return;
  }
  nd_rollout *r = &rc->r;
  const int i = rc->steps++;
  r->u[2 * i] = u[0];
  r->u[2 * i + 1] = u[1];
  r->ee[2 * i] = ee[0];
  r->ee[2 * i + 1] = ee[1];
  double *sp = r->sp + 6 * i;
  if (rc->have_sp) {
    sp[0] = rc->sp.p[0], sp[1] = rc->sp.p[1];
    sp[2] = rc->sp.v[0], sp[3] = rc->sp.v[1];
    sp[4] = rc->sp.a[0], sp[5] = rc->sp.a[1];
  } else {  /* no executor: the robot holds the sphere where it started */
    sp[0] = r->ee_pos[0], sp[1] = r->ee_pos[1];
    sp[2] = sp[3] = sp[4] = sp[5] = 0.0;
  }
  rc->step_us[i] = us;
}

void nd_recorder_state(nd_recorder *rc, const nd_rec_state *s) {
  if (!rc->on || rc->broken[0]) return;
  if (s->seq <= rc->last_seq) {
    snprintf(rc->broken, sizeof(rc->broken),
             "robot state seq went back from %lld to %lld (robot restarted?)",
             (long long)rc->last_seq, (long long)s->seq);
    return;
  }
  const int64_t gap = s->seq - rc->last_seq - 1;
  const int vel = rc->r.control == ND_CTRL_VELOCITY;
  const double u[2] = {vel ? s->ee_vel[0] : s->force[0], vel ? s->ee_vel[1] : s->force[1]};
  const double ee[2] = {s->ee_pos[0], s->ee_pos[1]};
  if (gap > ND_REC_GAP_FILL_MAX) {
    snprintf(rc->broken, sizeof(rc->broken),
             "%lld robot states lost in a row after seq %lld (at most %d are filled)",
             (long long)gap, (long long)rc->last_seq, ND_REC_GAP_FILL_MAX);
    return;
  }
  for (int64_t j = 1; j <= gap; j++) {
    const double f = (double)j / (double)(gap + 1);
    const double uf[2] = {rc->last_u[0] + f * (u[0] - rc->last_u[0]),
                          rc->last_u[1] + f * (u[1] - rc->last_u[1])};
    const double ef[2] = {rc->last_ee[0] + f * (ee[0] - rc->last_ee[0]),
                          rc->last_ee[1] + f * (ee[1] - rc->last_ee[1])};
    push(rc, uf, ef, rc->last_us + (int64_t)llround(f * (double)(s->utime - rc->last_us)));
  }
  rc->filled += gap;
  if (gap > rc->longest_gap) rc->longest_gap = gap;
  push(rc, u, ee, s->utime);
  rc->last_seq = s->seq;
  rc->last_us = s->utime;
  memcpy(rc->last_u, u, sizeof(u));
  memcpy(rc->last_ee, ee, sizeof(ee));
}

/* Frame k's pose, its quaternion on the side of the double cover nearer the quaternion ref
 * (NULL: as stored). */
static void frame_pose(const double *frame, int k, const double *ref, double p[ND_ROLLOUT_OBJ]) {
  memcpy(p, frame + ND_ROLLOUT_OBJ * k, ND_ROLLOUT_OBJ * sizeof(double));
  if (ref && p[3] * ref[0] + p[4] * ref[1] + p[5] * ref[2] + p[6] * ref[3] < 0)
    for (int c = 3; c < ND_ROLLOUT_OBJ; c++) p[c] = -p[c];
}

/* The pose's rate at frame k, per us, from its neighbours (quaternions aligned to ref):
 * the three-point difference for uneven spacing, exact for a quadratic; the one secant at
 * the first and last frame. */
static void frame_rate(const int64_t *us, const double *frame, int n, int k, const double *ref,
                       double m[ND_ROLLOUT_OBJ]) {
  const int lo = k > 0 ? k - 1 : k, hi = k + 1 < n ? k + 1 : k;
  double a[ND_ROLLOUT_OBJ], b[ND_ROLLOUT_OBJ], c[ND_ROLLOUT_OBJ];
  frame_pose(frame, lo, ref, a);
  frame_pose(frame, k, ref, b);
  frame_pose(frame, hi, ref, c);
  const double h0 = (double)(us[k] - us[lo]), h1 = (double)(us[hi] - us[k]);
  for (int i = 0; i < ND_ROLLOUT_OBJ; i++) {
    const double d0 = h0 > 0 ? (b[i] - a[i]) / h0 : 0, d1 = h1 > 0 ? (c[i] - b[i]) / h1 : 0;
    m[i] = h0 > 0 && h1 > 0 ? (d0 * h1 + d1 * h0) / (h0 + h1) : d0 + d1;
  }
}

/* Pose o at fraction s of the interval from pose a (rate ma) to b (mb), h us long. */
static void cubic(const double *a, const double *ma, const double *b, const double *mb,
                  double h, double s, double o[ND_ROLLOUT_OBJ]) {
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = 3 * s2 - 2 * s3,
               h11 = s3 - s2;
  for (int c = 0; c < ND_ROLLOUT_OBJ; c++)
    o[c] = h00 * a[c] + h10 * h * ma[c] + h01 * b[c] + h11 * h * mb[c];
  double n = 0;
  for (int c = 3; c < ND_ROLLOUT_OBJ; c++) n += o[c] * o[c];
  n = sqrt(n);
  for (int c = 3; c < ND_ROLLOUT_OBJ; c++) o[c] /= n;
}

void nd_recorder_join(const int64_t *frame_us, const double *frame, int nframes, int join,
                      const int64_t *t, int n, double *obj) {
  double a[ND_ROLLOUT_OBJ], b[ND_ROLLOUT_OBJ], ma[ND_ROLLOUT_OBJ], mb[ND_ROLLOUT_OBJ];
  int j = 0, seg = -1;
  for (int i = 0; i < n; i++) {
    while (j + 1 < nframes && frame_us[j + 1] <= t[i]) j++;
    const double *f0 = frame + ND_ROLLOUT_OBJ * j;
    double *o = obj + ND_ROLLOUT_OBJ * i;
    if (!(j + 1 < nframes && frame_us[j] <= t[i])) {
      memcpy(o, f0, ND_ROLLOUT_OBJ * sizeof(double));
      continue;
    }
    const double h = (double)(frame_us[j + 1] - frame_us[j]);
    const double s = (double)(t[i] - frame_us[j]) / h;
    if (join == ND_REC_JOIN_LINE) {
      const double *f1 = f0 + ND_ROLLOUT_OBJ;
      for (int c = 0; c < 3; c++) o[c] = f0[c] + s * (f1[c] - f0[c]);
      nd_quat_nlerp(f0 + 3, f1 + 3, s, o + 3);
      continue;
    }
    if (seg != j) {  /* a new frame interval: its ends and their rates */
      seg = j;
      frame_pose(frame, j, NULL, a);
      frame_pose(frame, j + 1, a + 3, b);
      frame_rate(frame_us, frame, nframes, j, a + 3, ma);
      frame_rate(frame_us, frame, nframes, j + 1, a + 3, mb);
    }
    cubic(a, ma, b, mb, h, s, o);
  }
}

int nd_recorder_finish(nd_recorder *rc, int outcome, const nd_rollout **out, char *why,
                       int len) {
  if (!rc->on) {
    snprintf(why, len, "no task was being recorded");
    return -1;
  }
  rc->on = 0;
  const double period =
      rc->steps ? 1e-6 * (double)(rc->last_us - rc->start_us) / (rc->steps + 0.0) : 0;
  if (rc->broken[0])
    snprintf(why, len, "%s", rc->broken);
  else if (rc->steps == 0)
    snprintf(why, len, "no robot state arrived during the task");
  else if (rc->filled > ND_REC_FILL_MAX_FRAC * rc->steps)
    snprintf(why, len, "%lld of %d steps lost (more than %.0f%% would be filled in)",
             (long long)rc->filled, rc->steps, 100 * ND_REC_FILL_MAX_FRAC);
  else if (rc->steps >= 100 && fabs(period - rc->dt) > ND_REC_DT_TOLERANCE * rc->dt)
    snprintf(why, len, "robot states came every %.3f ms, the record's dt is %.3f ms: a "
             "replay would run at the wrong rate", 1e3 * period, 1e3 * rc->dt);
  else {
    rc->r.outcome = outcome;
    nd_recorder_join(rc->frame_us, rc->frame, rc->nframes, rc->join, rc->step_us, rc->steps,
                     rc->r.obj);
    rc->r.n = rc->steps;
    *out = &rc->r;
    return 0;
  }
  return -1;
}
