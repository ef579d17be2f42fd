/* nds_world: the emulated worlds (nds_world.h): creation, the sphere on slide joints, the
 * Panda, their sensors. */
#include "nds_world.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_linalg.h"
#include "nd_math.h"
#include "nd_release.h"
#include "nd_rng.h"
#include "nds_ctrl.h"
#include "nds_state.h"

#define NJ NDS_PANDA_NJ

struct nds_world {
  nds_world_cfg cfg;
  mjModel *m;               /* owned through nm (sphere) or directly (arm) */
  mjData *d;
  nd_mocap mocap;
  nd_rng rng;               /* the arm's sensor noise */
  /* the sphere on slide joints */
  nds_model nm;
  nds_ctrl_cfg ctrl_cfg;
  nds_ctrl pid;
  nds_state init;           /* start (and reset) state */
  /* the arm */
  nds_panda panda;
  nds_panda_ctrl ctrl;
  nds_panda_monitor mon;
  int obj_qpos, obj_dof;
  double q0[NJ];            /* the arm's start posture */
  double z;                 /* the sphere's height */
  int stopped;
  nds_panda_reflex reflex;
  double q_hold[NJ];
};

void nds_world_cfg_default(nds_world_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->kind = NDS_WORLD_IDEAL;
  cfg->dt = 0.001;
  memcpy(cfg->theta, nd_theta_true, sizeof(cfg->theta));
  cfg->ee[0] = -0.10;
  nd_mocap_cfg_exact(&cfg->mocap);
  nds_scene_cfg_default(&cfg->object);
  nds_panda_cfg_default(&cfg->panda);
  cfg->seed = 1;
}

void nds_world_cfg_lab(nds_world_cfg *cfg) {
  nds_world_cfg_default(cfg);
  cfg->kind = NDS_WORLD_LAB;
  cfg->arm = 1;
  nd_mocap_cfg_lab(&cfg->mocap);
  /* A Panda's readings (doc/lab-world.md#sensing): encoder-scale position noise, the
   * differentiated velocity's noise, and the joint torque sensors' noise behind the force
   * estimate. */
  cfg->encoder_noise = 1e-5;
  cfg->velocity_noise = 1e-3;
  cfg->torque_noise = 0.05;
  /* The lab's box (doc/lab-world.md#object): a little larger and heavier than the model,
   * unevenly filled, on a stiffer contact, and nothing damps its tilt. */
  nds_scene_cfg *o = &cfg->object;
  o->obj_half[0] = 0.051, o->obj_half[1] = 0.0305, o->obj_half[2] = 0.025;
  o->obj_mass = 0.55;
  o->obj_com[0] = 0.008, o->obj_com[1] = -0.004, o->obj_com[2] = -0.004;
  o->solref[0] = 0.01, o->solref[1] = 1.0;
  o->solimp[0] = 0.95, o->solimp[1] = 0.99, o->solimp[2] = 0.001;
  o->tilt_damping = 0.0;
}

/* The sphere must start clear of the box, or the first contact throws the object. */
static int check_start(const nds_world_cfg *c, double ee_radius, char *err, int errlen) {
  const double *h = c->object.obj_half;
  const double d[2] = {c->ee[0] - c->obj[0], c->ee[1] - c->obj[1]};
  double l[2];  /* in the box frame */
  nd_rot2(cos(c->obj[2]), -sin(c->obj[2]), d, l);
  const double ex = fabs(l[0]) - h[0], ey = fabs(l[1]) - h[1];
  double gap = hypot(ex > 0 ? ex : 0, ey > 0 ? ey : 0);
  if (ex <= 0 && ey <= 0) gap = ex > ey ? ex : ey;
  if (gap < ee_radius) {
    snprintf(err, errlen,
             "the sphere at %g,%g (radius %g m) overlaps the object at %g,%g,%g (half sizes "
             "%g x %g m)", c->ee[0], c->ee[1], ee_radius, c->obj[0], c->obj[1], c->obj[2],
             h[0], h[1]);
    return -1;
  }
  return 0;
}

/* The sphere on slide joints: the built-in scene (with cfg's object) at cfg->dt, or the
 * file (its timestep unless dt > 0). */
static int load_sphere(nds_world *w, char *err, int errlen) {
  const nds_world_cfg *c = &w->cfg;
  nds_scene_cfg sc = c->object;
  memcpy(sc.theta, c->theta, sizeof(sc.theta));
  if (!c->model_path) {
    sc.timestep = c->dt;
    if (nds_model_init(&w->nm, &sc, err, errlen)) return -1;
  } else {
    /* MuJoCo's parser reports a missing file as an XML error: say it plainly. */
    FILE *probe = fopen(c->model_path, "r");
    if (!probe) {
      snprintf(err, errlen, "cannot open %s: %s", c->model_path, strerror(errno));
      return -1;
    }
    fclose(probe);
    char why[400];
    if (nds_model_load_file(&w->nm, c->model_path, &sc, why, sizeof(why))) {
      snprintf(err, errlen, "cannot use %s: %s", c->model_path, why);
      return -1;
    }
    if (c->dt > 0) w->nm.m->opt.timestep = c->dt;
  }
  w->m = w->nm.m;
  w->cfg.object.obj_half[0] = w->nm.cfg.obj_half[0];
  w->cfg.object.obj_half[1] = w->nm.cfg.obj_half[1];
  w->cfg.object.obj_half[2] = w->nm.cfg.obj_half[2];
  w->cfg.object.ee_radius = w->nm.cfg.ee_radius;
  w->obj_qpos = w->nm.obj_qpos;
  w->obj_dof = w->nm.obj_dof;
  if (check_start(c, w->nm.cfg.ee_radius, err, errlen) || !(w->d = mj_makeData(w->m))) {
    if (!w->d && !err[0]) snprintf(err, errlen, "out of memory for the world's mjData");
    return -1;
  }
  nds_ctrl_cfg_default(&w->ctrl_cfg);
  nds_state_rest(&w->nm, c->obj[0], c->obj[1], c->obj[2], c->ee, &w->init);
  if (nds_state_set(&w->nm, w->d, &w->init, err, errlen)) return -1;
  nds_ctrl_reset(&w->pid, w->m->body_mass[w->nm.ee_body]);
  return 0;
}

/* The object at rest flat on the table at (x, y, yaw). */
static void put_object(nds_world *w, double x, double y, double yaw) {
  double *q = w->d->qpos + w->obj_qpos;
  q[0] = x, q[1] = y, q[2] = w->cfg.object.obj_half[2];
  nd_yaw_quat(yaw, q + 3);
  memset(w->d->qvel + w->obj_dof, 0, 6 * sizeof(double));
  memset(w->d->qacc_warmstart + w->obj_dof, 0, 6 * sizeof(double));
}

/* Object and arm at their start, at rest. */
static void arm_start(nds_world *w) {
  const double *o = w->cfg.obj;
  mj_resetData(w->m, w->d);
  put_object(w, o[0], o[1], o[2]);
  nds_panda_set_q(&w->panda, w->m, w->d, w->q0);  /* also runs mj_forward */
}

/* The Panda with its sphere: where it starts (IK of cfg->ee), its controller and reflexes. */
static int load_arm(nds_world *w, char *err, int errlen) {
  const nds_world_cfg *c = &w->cfg;
  nds_scene_cfg sc = c->object;
  memcpy(sc.theta, c->theta, sizeof(sc.theta));
  sc.timestep = c->dt > 0 ? c->dt : 0.001;
  if (c->model_path) {
    snprintf(err, errlen, "a model file has no arm: use it without the arm");
    return -1;
  }
  sc.ee_radius = c->panda.ee_radius;
  if (!(w->m = nds_panda_scene_load(&c->panda, &sc, 1, err, errlen)) ||
      nds_panda_resolve(&w->panda, w->m, &c->panda, err, errlen))
    return -1;
  /* The planning model's tilt damping is a model of its own, set after loading as there. */
  const int ob = mj_name2id(w->m, mjOBJ_BODY, "object");
  const int oj = w->m->body_jntadr[ob];
  w->obj_qpos = w->m->jnt_qposadr[oj];
  w->obj_dof = w->m->jnt_dofadr[oj];
  w->m->dof_damping[w->obj_dof + 3] = w->m->dof_damping[w->obj_dof + 4] = sc.tilt_damping;
  w->cfg.object.ee_radius = c->panda.ee_radius;
  w->z = nds_panda_push_height(&c->panda);
  const double target[3] = {c->ee[0], c->ee[1], w->z};
  char why[300];
  if (nds_panda_ik(&c->panda, target, NULL, w->q0, why, sizeof(why))) {
    snprintf(err, errlen, "the arm cannot put the sphere at %g,%g: %s", c->ee[0], c->ee[1], why);
    return -1;
  }
  if (check_start(c, c->panda.ee_radius, err, errlen)) return -1;
  nds_panda_gains g;
  nds_panda_gains_default(&g);
  if (!(w->d = mj_makeData(w->m)) || nds_panda_ctrl_init(&w->ctrl, w->m, &g, err, errlen)) {
    if (!w->d) snprintf(err, errlen, "out of memory for the world's mjData");
    return -1;
  }
  nds_panda_monitor_reset(&w->mon, w->m->opt.timestep, NDS_PANDA_ACCEL_WINDOW_PUSH);
  arm_start(w);
  return 0;
}

nds_world *nds_world_create(const nds_world_cfg *cfg, char *err, int errlen) {
  if (!(cfg->dt >= 0 && cfg->dt <= 0.05) || !(cfg->encoder_noise >= 0) ||
      !(cfg->velocity_noise >= 0) || !(cfg->torque_noise >= 0)) {
    snprintf(err, errlen, "world: dt %g s or a sensor noise out of range", cfg->dt);
    return NULL;
  }
  if (nd_mocap_cfg_check(&cfg->mocap, err, errlen)) return NULL;
  nds_world *w = calloc(1, sizeof(*w));
  if (!w) {
    snprintf(err, errlen, "out of memory for the world");
    return NULL;
  }
  err[0] = '\0';
  w->cfg = *cfg;
  if ((cfg->arm ? load_arm : load_sphere)(w, err, errlen)) goto fail;
  const double dt = w->m->opt.timestep;
  w->cfg.dt = dt;
  if (cfg->mocap.rate * dt > 1.0 + 1e-9) {
    snprintf(err, errlen, "motion capture at %g Hz exceeds the world's step rate %g Hz",
             cfg->mocap.rate, 1.0 / dt);
    goto fail;
  }
  nd_rng_seed(&w->rng, cfg->seed, 0x726f626f74ULL);  /* "robot" */
  /* The first frame is due at the first step's end; a frame is captured at a step's end. */
  nd_mocap_init(&w->mocap, &cfg->mocap, w->d->time + dt);
  return w;
fail:
  nds_world_free(w);
  return NULL;
}

void nds_world_free(nds_world *w) {
  if (!w) return;
  if (w->d) mj_deleteData(w->d);
  nds_panda_ctrl_free(&w->ctrl);
  if (w->cfg.arm) {
    if (w->m) mj_deleteModel(w->m);
  } else {
    nds_model_free(&w->nm);
  }
  free(w);
}

const nds_world_cfg *nds_world_config(const nds_world *w) { return &w->cfg; }
double nds_world_time(const nds_world *w) { return w->d->time; }
const mjModel *nds_world_mj_model(const nds_world *w) { return w->m; }
const mjData *nds_world_mj_data(const nds_world *w) { return w->d; }

void nds_world_sizes(const nds_world *w, double obj_half[3], double *ee_radius) {
  memcpy(obj_half, w->cfg.object.obj_half, 3 * sizeof(double));
  *ee_radius = w->cfg.object.ee_radius;
}

void nds_world_ee(const nds_world *w, double ee[2]) {
  if (w->cfg.arm) {
    /* From the joints as they are now (mjData's kinematics are a step behind after
     * mj_step2). */
    double q[NJ], p[3];
    nds_panda_get_q(&w->panda, w->d, q, NULL);
    nds_panda_fk(&w->cfg.panda, q, NULL, NULL, p);
    ee[0] = p[0], ee[1] = p[1];
    return;
  }
  for (int k = 0; k < 2; k++) ee[k] = w->d->qpos[w->nm.ee_qpos[k]];
}

void nds_world_resume(nds_world *w) {
  if (!w->stopped) return;
  w->stopped = 0;
  memset(&w->reflex, 0, sizeof(w->reflex));
  nds_panda_monitor_reset(&w->mon, w->m->opt.timestep, NDS_PANDA_ACCEL_WINDOW_PUSH);
}

double nds_world_place(nds_world *w, double x, double y, double yaw, double clear) {
  const nd_release_box b = {x, y, yaw, {w->cfg.object.obj_half[0], w->cfg.object.obj_half[1]}};
  double ee[2], n[2];
  nds_world_ee(w, ee);
  const double gap = nd_release_gap(&b, w->cfg.object.ee_radius, ee, n);
  if (gap >= clear) put_object(w, x, y, yaw);
  return gap;
}

void nds_world_motion_start(nds_world *w) { nds_panda_monitor_new_motion(&w->mon); }

/* MuJoCo resets mjData to qpos0 by itself on a bad qacc and only counts a warning: look at
 * both the counters (cleared before each step) and the configuration. */
static int diverged(const mjModel *m, const mjData *d) {
  if (d->warning[mjWARN_BADQPOS].number || d->warning[mjWARN_BADQVEL].number ||
      d->warning[mjWARN_BADQACC].number)
    return 1;
  return !nd_all_finite(d->qpos, m->nq) || !nd_all_finite(d->qvel, m->nv);
}

/* One step of the sphere on slide joints under the tracking controller. */
static void step_sphere(nds_world *w, const double sp[2][4], nds_world_robot *r) {
  nds_state s;
  nds_state_get(&w->nm, w->d, &s);
  double f[2];
  nds_ctrl_pid(&w->ctrl_cfg, &w->pid, sp, s.ee_pos, s.ee_vel, w->m->opt.timestep, f);
  w->d->qfrc_applied[w->nm.ee_dof[0]] = f[0];
  w->d->qfrc_applied[w->nm.ee_dof[1]] = f[1];
  mj_step(w->m, w->d);
  nds_state_get(&w->nm, w->d, &s);
  for (int k = 0; k < 2; k++) {
    r->ee_pos[k] = s.ee_pos[k];
    r->ee_vel[k] = s.ee_vel[k];
    r->ee_force[k] = f[k];
  }
  r->ee_pos[2] = w->nm.ee_height;
}

/* One step of the arm: its reflexes on the readings and the setpoint, the impedance law (or
 * the brake), then what its sensors say: the sphere from the forward kinematics of the
 * joint readings, its velocity through the Jacobian, and the force from the joint torques
 * less the model's gravity and Coriolis, as a robot estimates it (inertial forces show up
 * in it while the arm accelerates). */
static int step_arm(nds_world *w, const double sp[2][4], nds_world_robot *r) {
  const mjModel *m = w->m;
  mjData *d = w->d;
  const nds_world_cfg *c = &w->cfg;
  mj_step1(m, d);
  double q[NJ], dq[NJ], qm[NJ], dqm[NJ], tau[NJ], bias[NJ];
  nds_panda_get_q(&w->panda, d, q, dq);
  for (int i = 0; i < NJ; i++) {
    qm[i] = q[i] + c->encoder_noise * nd_rng_normal(&w->rng);
    dqm[i] = dq[i] + c->velocity_noise * nd_rng_normal(&w->rng);
    bias[i] = d->qfrc_bias[w->panda.dof[i]];
  }
  const double p_des[3] = {sp[0][0], sp[1][0], w->z}, v_des[3] = {sp[0][1], sp[1][1], 0};
  const double a_des[3] = {sp[0][2], sp[1][2], 0};
  int stopped_now = 0;
  if (!w->stopped && nds_panda_monitor_check(&w->mon, qm, dqm, p_des, &w->reflex)) {
    w->stopped = stopped_now = 1;
    memcpy(w->q_hold, qm, sizeof(qm));
  }
  if (w->stopped) nds_panda_ctrl_brake(&w->panda, d, w->q_hold, tau);
  else nds_panda_ctrl_impedance(&w->ctrl, &w->panda, m, d, p_des, v_des, a_des, tau);
  nds_panda_apply(&w->panda, d, tau);
  mj_step2(m, d);

  double J[35], JJ[9], f[3] = {0, 0, 0};
  nds_panda_fk(&c->panda, qm, NULL, NULL, r->ee_pos);
  nds_panda_jac(&c->panda, qm, J);
  for (int k = 0; k < 3; k++) {
    r->ee_vel[k] = 0;
    for (int i = 0; i < NJ; i++) {
      r->ee_vel[k] += J[k * NJ + i] * dqm[i];
      f[k] += J[k * NJ + i] * (tau[i] + c->torque_noise * nd_rng_normal(&w->rng) - bias[i]);
    }
  }
  /* F = (J J')^-1 J (tau - bias): the static estimate through the translation rows. */
  nd_aat(J, 3, NJ, 1e-9, JJ);
  if (nd_chol(JJ, 3) == 0) nd_chol_solve(JJ, 3, f, r->ee_force);
  r->arm = 1;
  memcpy(r->q, qm, sizeof(qm));
  memcpy(r->dq, dqm, sizeof(dqm));
  memcpy(r->tau, tau, sizeof(tau));
  return stopped_now;
}

void nds_world_step(nds_world *w, const double sp[2][4], nds_world_out *out) {
  mjData *d = w->d;
  nds_world_robot *r = &out->robot;
  memset(r, 0, sizeof(*r));
  for (int k = mjWARN_BADQPOS; k <= mjWARN_BADQACC; k++) d->warning[k].number = 0;
  out->stopped_now = w->cfg.arm ? step_arm(w, sp, r) : (step_sphere(w, sp, r), 0);
  out->reset = diverged(w->m, d);
  if (out->reset) {
    const double t = d->time;  /* world time goes on: the motion capture keeps its clock */
    if (w->cfg.arm) {
      arm_start(w);
      w->stopped = 0;
    } else {
      char err[128];  /* the start state was checked at create */
      nds_state_set(&w->nm, d, &w->init, err, sizeof(err));
      mj_forward(w->m, d);
      nds_ctrl_reset(&w->pid, w->m->body_mass[w->nm.ee_body]);
    }
    d->time = t;
  }
  r->stopped = w->stopped;
  r->reflex = w->reflex;

  const double *obj = d->qpos + w->obj_qpos;
  double ee[3];
  nds_world_ee(w, ee);
  ee[2] = r->ee_pos[2];
  nd_mocap_capture(&w->mocap, d->time, obj, obj + 3, ee);
  nd_mocap_frame mf[NDS_WORLD_MAX_FRAMES];
  out->nframes = nd_mocap_release(&w->mocap, d->time, mf, NDS_WORLD_MAX_FRAMES);
  for (int i = 0; i < out->nframes; i++) {
    nds_world_frame *fr = &out->frame[i];
    fr->index = mf[i].index;
    fr->capture_t = mf[i].t_capture;
    memcpy(fr->obj_pos, mf[i].obj_pos, sizeof(fr->obj_pos));
    memcpy(fr->obj_quat, mf[i].obj_quat, sizeof(fr->obj_quat));
    memcpy(fr->ee_pos, mf[i].ee_pos, sizeof(fr->ee_pos));
  }
}
