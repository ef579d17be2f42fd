/* nds_rollout: min-snap setpoints -> tracking controller -> mj_step, alone or on a pool. */
#include "nds_rollout.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"
#include "nd_snap.h"

/* MuJoCo counts warnings in d->warning and prints one only when its counter is zero. When
 * qpos, qvel or qacc go bad it also resets the data (mj_resetData zeroes every counter)
 * and then counts that warning once more. Starting every counter at this value therefore
 * makes any warning during the rollout, reset or not, leave some counter != START, and
 * keeps MuJoCo from printing for rollouts whose divergence we report anyway. */
#define WARN_START 2

/* A rollout longer than this many steps is an input error, not a plan. */
#define MAX_STEPS 100000000L

static void fail(nds_rollout_out *out) {
  memset(out, 0, sizeof(*out));
  out->diverged = 1;
}

/* Free flight's reach: the sphere is far when its centre is beyond the object's corner
 * circle (the half diagonal), its radius, this margin and twice its step's travel. The
 * object is at rest when MuJoCo's last step left it with no velocity or acceleration
 * component above the thresholds: settled on its soft contact, not merely still (a box
 * set down at rest sinks ~0.1 mm into the table over its first steps, and frozen before
 * that it meets the sphere while still settling: 1-2 cm off after a push). */
#define FF_MARGIN 0.005
#define FF_REST_V 1e-4  /* m/s */
#define FF_REST_W 1e-3  /* rad/s */
#define FF_REST_A 1e-2  /* m/s^2 */
#define FF_REST_AW 1e-1 /* rad/s^2 */

/* 1 if the step from d may skip MuJoCo: the sphere at pos, moving at vel, is out of reach
 * of an object at rest; stepped is 1 once MuJoCo has stepped d in this rollout. */
static int free_to_fly(const nds_model *nm, const mjData *d, int stepped, const double pos[2],
                       const double vel[2], double reach, double dt) {
  if (!stepped) return 0;
  const double *ov = d->qvel + nm->obj_dof, *oa = d->qacc + nm->obj_dof;
  for (int k = 0; k < 3; k++)
    if (fabs(ov[k]) > FF_REST_V || fabs(ov[3 + k]) > FF_REST_W || fabs(oa[k]) > FF_REST_A ||
        fabs(oa[3 + k]) > FF_REST_AW)
      return 0;
  const double *op = d->qpos + nm->obj_qpos;
  const double dist = hypot(pos[0] - op[0], pos[1] - op[1]);
  return dist > reach + 2.0 * dt * hypot(vel[0], vel[1]);
}

/* The sphere's position and velocity in d; off is its body offset from its joints' zero. */
static void ee_read(const nds_model *nm, const mjData *d, const double off[2], double pos[2],
                    double vel[2]) {
  for (int k = 0; k < 2; k++) {
    pos[k] = d->qpos[nm->ee_qpos[k]] + off[k];
    vel[k] = d->qvel[nm->ee_dof[k]];
  }
}

static void ee_offset(const nds_model *nm, double off[2]) {
  for (int k = 0; k < 2; k++)
    off[k] = nm->m->body_pos[3 * nm->ee_body + k] - nm->m->qpos0[nm->ee_qpos[k]];
}

/* The object's pose (x, y, yaw) in d into at[3]. */
static void obj_pose(const nds_model *nm, const mjData *d, double at[3]) {
  const mjtNum *q = d->qpos + nm->obj_qpos;
  at[0] = q[0];
  at[1] = q[1];
  at[2] = nd_quat_yaw(q + 3);
}

static int warned(const mjData *d) {
  for (int w = 0; w < mjNWARNING; w++)
    if (d->warning[w].number != WARN_START) return 1;
  return 0;
}

void nds_rollout(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl,
                 const nds_state *s0, const double sp0[2][4], const double *keys, int M,
                 double T, nds_rollout_out *out) {
  nds_rollout_ff(nm, d, ctrl, s0, sp0, keys, M, T, 0, out);
}

void nds_rollout_ff(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl,
                    const nds_state *s0, const double sp0[2][4], const double *keys, int M,
                    double T, int free_flight, nds_rollout_out *out) {
  const mjModel *m = nm->m;
  char err[64];
  memset(out, 0, sizeof(*out)); /* padding too, so results compare bytewise */
  double dt = m->opt.timestep;
  double steps = round(M * T / dt);
  if (M < 1 || M > ND_MAX_KEYS || !(T > 0) || !(steps >= 1 && steps <= MAX_STEPS) ||
      !nd_all_finite(&sp0[0][0], 8) || !nd_all_finite(keys, 4 * M) ||
      nds_state_set(nm, d, s0, err, sizeof(err))) {
    fail(out);
    return;
  }
  long nsteps = (long)steps;

  nd_snap_seg seg[ND_MAX_KEYS];
  double s[2][4];
  nd_snap_chain(seg, sp0, keys, M, T);

  for (int i = 0; i < mjNWARNING; i++) d->warning[i].number = WARN_START;
  nds_ctrl c;
  nds_ctrl_reset(&c, m->body_mass[nm->ee_body]);
  double acc_sum = 0, v2_peak = 0, a2_peak = 0;
  double off[2], pos[2], vel[2], f[2];
  ee_offset(nm, off);

  /* The sphere's two slide dofs move its mass alone (nds_model checks: a leaf body, no
   * armature); without damping MuJoCo's Euler step for them is v += dt f / m. */
  const double *half = nm->cfg.obj_half;
  const double reach = nm->cfg.ee_radius + hypot(half[0], half[1]) + FF_MARGIN;
  const double inv_m = 1.0 / m->body_mass[nm->ee_body];
  const int ff = free_flight && m->dof_damping[nm->ee_dof[0]] == 0 &&
                 m->dof_damping[nm->ee_dof[1]] == 0;
  long skipped = 0;
  int diverged = 0;
  /* The next horizon sample, and the step count it falls after ((k + 1) / NS of nsteps). */
  int next = 0;
  long next_at = nsteps / NDS_ROLLOUT_NS;
  for (long n = 0; n < nsteps && !diverged; n++) {
    /* Zero-order hold: the setpoint at the step's start drives the whole step, as the
     * executor's 1 kHz setpoint does on the robot. Time from the step index, not from
     * d->time, so long rollouts do not accumulate rounding. */
    double t = n * dt;
    int i = (int)(t / T);
    if (i > M - 1) i = M - 1;
    nd_snap_seg_eval(&seg[i], t - i * T, s);

    double v2 = s[0][ND_V] * s[0][ND_V] + s[1][ND_V] * s[1][ND_V];
    double a2 = s[0][ND_A] * s[0][ND_A] + s[1][ND_A] * s[1][ND_A];
    acc_sum += a2;
    if (v2 > v2_peak) v2_peak = v2;
    if (a2 > a2_peak) a2_peak = a2;

    ee_read(nm, d, off, pos, vel);
    nds_ctrl_pid(ctrl, &c, (const double(*)[4])s, pos, vel, dt, f);
    /* The step moves the sphere by dt times its velocity after the step. */
    const double vnext[2] = {vel[0] + dt * f[0] * inv_m, vel[1] + dt * f[1] * inv_m};
    if (ff && free_to_fly(nm, d, n > skipped, pos, vnext, reach, dt)) {
      for (int k = 0; k < 2; k++) {
        d->qvel[nm->ee_dof[k]] = vnext[k];
        d->qpos[nm->ee_qpos[k]] += dt * vnext[k];
      }
      d->time += dt;
      skipped++;
    } else {
      d->qfrc_applied[nm->ee_dof[0]] = f[0];
      d->qfrc_applied[nm->ee_dof[1]] = f[1];
      mj_step(m, d);
      diverged = warned(d);
    }
    /* A sample due before the first step (under NS steps) takes the pose after it. */
    while (next < NDS_ROLLOUT_NS && n + 1 >= next_at) {
      for (int k = 0; k < 2; k++) out->ee_at[next][k] = d->qpos[nm->ee_qpos[k]] + off[k];
      obj_pose(nm, d, out->obj_at[next++]);
      next_at = (long)(next + 1) * nsteps / NDS_ROLLOUT_NS;
    }
  }
  if (!diverged && !(nd_all_finite(d->qpos, m->nq) && nd_all_finite(d->qvel, m->nv)))
    diverged = 1;
  if (diverged) {
    fail(out);
    return;
  }

  nds_state sf;
  nds_state_get(nm, d, &sf);
  out->obj_xy[0] = sf.obj_pos[0];
  out->obj_xy[1] = sf.obj_pos[1];
  out->obj_yaw = nds_state_yaw(&sf);
  out->ee_xy[0] = sf.ee_pos[0];
  out->ee_xy[1] = sf.ee_pos[1];
  out->acc_sq_mean = acc_sum / nsteps;
  out->v_peak = sqrt(v2_peak);
  out->a_peak = sqrt(a2_peak);
  out->diverged = 0;
  out->steps = (int)nsteps;
  out->skipped = (int)skipped;
}

int nds_predict(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl, const nds_state *s0,
                const double (*sp)[2][4], int n, nds_state *s1, char *err, int errlen) {
  const mjModel *m = nm->m;
  if (n < 0 || (n > 0 && !nd_all_finite(&sp[0][0][0], 8 * n))) {
    snprintf(err, errlen, "predict: %d setpoints, or one not finite", n);
    return -1;
  }
  if (nds_state_set(nm, d, s0, err, errlen)) return -1;
  for (int i = 0; i < mjNWARNING; i++) d->warning[i].number = WARN_START;
  nds_ctrl c;
  nds_ctrl_reset(&c, m->body_mass[nm->ee_body]);
  double off[2], pos[2], vel[2], f[2];
  ee_offset(nm, off);
  for (int i = 0; i < n; i++) {
    ee_read(nm, d, off, pos, vel);
    nds_ctrl_pid(ctrl, &c, sp[i], pos, vel, m->opt.timestep, f);
    d->qfrc_applied[nm->ee_dof[0]] = f[0];
    d->qfrc_applied[nm->ee_dof[1]] = f[1];
    mj_step(m, d);
    if (warned(d) || !nd_all_finite(d->qpos, m->nq) || !nd_all_finite(d->qvel, m->nv)) {
      snprintf(err, errlen, "predict: the model diverged at step %d of %d", i + 1, n);
      return -1;
    }
  }
  nds_state_get(nm, d, s1);
  return 0;
}

/* ---- batches on the pool ---- */

struct nds_batch {
  nd_pool *pool;
  int nworkers;
  nds_model *models;
  mjData **data;
  /* The current call's arguments, read by the tasks. */
  const nds_ctrl_cfg *ctrl;
  const nds_state *s0;
  const double (*sp0)[4];
  const double *keys;
  int M;
  double T;
  nds_rollout_out *out;
  int free_flight;
};

nds_batch *nds_batch_create(const nds_model *proto, nd_pool *pool, char *err, int errlen) {
  nds_batch *b = calloc(1, sizeof(*b));
  if (!b) goto oom;
  b->pool = pool;
  b->nworkers = nd_pool_size(pool);
  b->models = calloc(b->nworkers, sizeof(*b->models));
  b->data = calloc(b->nworkers, sizeof(*b->data));
  if (!b->models || !b->data) goto oom;
  for (int w = 0; w < b->nworkers; w++) {
    if (nds_model_copy(&b->models[w], proto, err, errlen)) {
      nds_batch_free(b);
      return NULL;
    }
    b->data[w] = mj_makeData(b->models[w].m);
    if (!b->data[w]) goto oom;
  }
  return b;
oom:
  snprintf(err, errlen, "batch: out of memory");
  nds_batch_free(b);
  return NULL;
}

void nds_batch_free(nds_batch *b) {
  if (!b) return;
  for (int w = 0; w < b->nworkers; w++) {
    if (b->data && b->data[w]) mj_deleteData(b->data[w]);
    if (b->models) nds_model_free(&b->models[w]);
  }
  free(b->data);
  free(b->models);
  free(b);
}

nd_pool *nds_batch_pool(nds_batch *b) { return b->pool; }
nds_model *nds_batch_model(nds_batch *b, int worker) { return &b->models[worker]; }
mjData *nds_batch_data(nds_batch *b, int worker) { return b->data[worker]; }

int nds_batch_set_theta(nds_batch *b, const double theta[ND_NTHETA], char *err, int errlen) {
  /* Checked once up front, so no model is left with a different theta than the others. */
  if (nd_theta_check(theta, err, errlen)) return -1;
  for (int w = 0; w < b->nworkers; w++)
    if (nds_theta_apply(&b->models[w], theta, err, errlen)) return -1;
  return 0;
}

void nds_batch_set_free_flight(nds_batch *b, int on) { b->free_flight = on; }

static void batch_task(void *ctx, int task, int worker) {
  nds_batch *b = ctx;
  nds_rollout_ff(&b->models[worker], b->data[worker], b->ctrl, b->s0, b->sp0,
                 b->keys + (size_t)task * 4 * b->M, b->M, b->T, b->free_flight, &b->out[task]);
}

void nds_batch_rollouts(nds_batch *b, const nds_ctrl_cfg *ctrl, const nds_state *s0,
                        const double sp0[2][4], const double *keys, int n, int M, double T,
                        nds_rollout_out *out) {
  b->ctrl = ctrl;
  b->s0 = s0;
  b->sp0 = sp0;
  b->keys = keys;
  b->M = M;
  b->T = T;
  b->out = out;
  nd_pool_run(b->pool, n, batch_task, b);
}
