/* nds_world: the ideal world (nds_world.h). */
#include "nds_world.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct nds_world {
  nds_world_cfg cfg;
  nds_model nm;
  mjData *d;
  nds_ctrl_cfg ctrl_cfg;
  nds_ctrl pid;
  nds_state init;           /* start (and reset) state */
  nd_mocap mocap;
};

void nds_world_cfg_default(nds_world_cfg *cfg) {
  memset(cfg, 0, sizeof(*cfg));
  cfg->kind = NDS_WORLD_IDEAL;
  cfg->dt = 0.001;
  memcpy(cfg->theta, nd_theta_true, sizeof(cfg->theta));
  cfg->ee[0] = -0.10;
  nd_mocap_cfg_exact(&cfg->mocap);
}

/* The sphere must start clear of the box, or the first contact throws the object. */
static int check_start(const nds_model *nm, const nds_world_cfg *c, char *err, int errlen) {
  const double dx = c->ee[0] - c->obj[0], dy = c->ee[1] - c->obj[1];
  const double cy = cos(c->obj[2]), sy = sin(c->obj[2]);
  const double lx = cy * dx + sy * dy, ly = -sy * dx + cy * dy;  /* in the box frame */
  const double ex = fabs(lx) - nm->cfg.obj_half[0], ey = fabs(ly) - nm->cfg.obj_half[1];
  double gap = hypot(ex > 0 ? ex : 0, ey > 0 ? ey : 0);
  if (ex <= 0 && ey <= 0) gap = ex > ey ? ex : ey;
  if (gap < nm->cfg.ee_radius) {
    snprintf(err, errlen,
             "the sphere at %g,%g (radius %g m) overlaps the object at %g,%g,%g (half sizes "
             "%g x %g m)",
             c->ee[0], c->ee[1], nm->cfg.ee_radius, c->obj[0], c->obj[1], c->obj[2],
             nm->cfg.obj_half[0], nm->cfg.obj_half[1]);
    return -1;
  }
  return 0;
}

/* Load the scene: the built-in one at cfg->dt, or the file (its timestep unless dt > 0). */
static int load(nds_world *w, char *err, int errlen) {
  const nds_world_cfg *c = &w->cfg;
  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  memcpy(sc.theta, c->theta, sizeof(sc.theta));
  if (!c->model_path) {
    sc.timestep = c->dt;
    return nds_model_init(&w->nm, &sc, err, errlen);
  }
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
  return 0;
}

nds_world *nds_world_create(const nds_world_cfg *cfg, char *err, int errlen) {
  if (!(cfg->dt >= 0 && cfg->dt <= 0.05)) {
    snprintf(err, errlen, "world: dt %g s out of range", cfg->dt);
    return NULL;
  }
  if (nd_mocap_cfg_check(&cfg->mocap, err, errlen)) return NULL;
  nds_world *w = calloc(1, sizeof(*w));
  if (!w) {
    snprintf(err, errlen, "out of memory for the world");
    return NULL;
  }
  w->cfg = *cfg;
  if (load(w, err, errlen)) goto fail;
  const double dt = w->nm.m->opt.timestep;
  w->cfg.dt = dt;
  if (cfg->mocap.rate * dt > 1.0 + 1e-9) {
    snprintf(err, errlen, "motion capture at %g Hz exceeds the world's step rate %g Hz",
             cfg->mocap.rate, 1.0 / dt);
    goto fail;
  }
  if (check_start(&w->nm, cfg, err, errlen)) goto fail;
  if (!(w->d = mj_makeData(w->nm.m))) {
    snprintf(err, errlen, "out of memory for the world's mjData");
    goto fail;
  }
  nds_ctrl_cfg_default(&w->ctrl_cfg);
  nds_state_rest(&w->nm, cfg->obj[0], cfg->obj[1], cfg->obj[2], cfg->ee, &w->init);
  if (nds_state_set(&w->nm, w->d, &w->init, err, errlen)) goto fail;
  mj_forward(w->nm.m, w->d);
  nds_ctrl_reset(&w->pid);
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
  nds_model_free(&w->nm);
  free(w);
}

const nds_model *nds_world_model(const nds_world *w) { return &w->nm; }
const nds_world_cfg *nds_world_config(const nds_world *w) { return &w->cfg; }
double nds_world_time(const nds_world *w) { return w->d->time; }

void nds_world_ee(const nds_world *w, double ee[2]) {
  for (int k = 0; k < 2; k++) ee[k] = w->d->qpos[w->nm.ee_qpos[k]];
}

/* MuJoCo resets mjData to qpos0 by itself on a bad qacc and only counts a warning: look at
 * both the counters (cleared before each step) and the configuration. */
static int diverged(const mjModel *m, const mjData *d) {
  if (d->warning[mjWARN_BADQPOS].number || d->warning[mjWARN_BADQVEL].number ||
      d->warning[mjWARN_BADQACC].number)
    return 1;
  for (int i = 0; i < m->nq; i++)
    if (!isfinite(d->qpos[i])) return 1;
  for (int i = 0; i < m->nv; i++)
    if (!isfinite(d->qvel[i])) return 1;
  return 0;
}

void nds_world_step(nds_world *w, const double sp[2][4], nds_world_out *out) {
  const mjModel *m = w->nm.m;
  mjData *d = w->d;
  nds_state s;
  nds_state_get(&w->nm, d, &s);
  double f[2];
  nds_ctrl_pid(&w->ctrl_cfg, &w->pid, sp, s.ee_pos, s.ee_vel, m->opt.timestep, f);
  d->qfrc_applied[w->nm.ee_dof[0]] = f[0];
  d->qfrc_applied[w->nm.ee_dof[1]] = f[1];
  for (int k = mjWARN_BADQPOS; k <= mjWARN_BADQACC; k++) d->warning[k].number = 0;
  mj_step(m, d);
  out->reset = diverged(m, d);
  if (out->reset) {
    char err[128];  /* the start state was checked at create */
    nds_state_set(&w->nm, d, &w->init, err, sizeof(err));
    mj_forward(m, d);
    nds_ctrl_reset(&w->pid);
    f[0] = f[1] = 0.0;
  }
  nds_state_get(&w->nm, d, &s);

  nds_world_robot *r = &out->robot;
  memset(r, 0, sizeof(*r));
  for (int k = 0; k < 2; k++) {
    r->ee_pos[k] = s.ee_pos[k];
    r->ee_vel[k] = s.ee_vel[k];
    r->ee_force[k] = f[k];
  }
  r->ee_pos[2] = w->nm.ee_height;

  const double ee[3] = {s.ee_pos[0], s.ee_pos[1], w->nm.ee_height};
  nd_mocap_capture(&w->mocap, d->time, s.obj_pos, s.obj_quat, ee);
  nd_mocap_frame mf[NDS_WORLD_MAX_FRAMES];
  out->nframes = nd_mocap_release(&w->mocap, d->time, mf, NDS_WORLD_MAX_FRAMES);
  for (int i = 0; i < out->nframes; i++) {
    nds_world_frame *fr = &out->frame[i];
    fr->capture_t = mf[i].t_capture;
    memcpy(fr->obj_pos, mf[i].obj_pos, sizeof(fr->obj_pos));
    memcpy(fr->obj_quat, mf[i].obj_quat, sizeof(fr->obj_quat));
    memcpy(fr->ee_pos, mf[i].ee_pos, sizeof(fr->ee_pos));
  }
}
