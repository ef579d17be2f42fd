/* scene: the world nudge-view draws, as a MuJoCo model (view.h). Each world kind has one
 * builder; everything after it (posing, drawing) reads only the indices set here. */
#include <stdio.h>
#include <string.h>

#include "view.h"

/* Colours chosen to tell the parts apart at a glance and by a test's colour thresholds:
 * a light table, a blue box, a red sphere (the ghosts and paths in draw.c use green,
 * orange, yellow and cyan). */
static const float rgba_table[4] = {0.82f, 0.82f, 0.78f, 1.0f};
static const float rgba_object[4] = {0.15f, 0.35f, 0.85f, 1.0f};
static const float rgba_ee[4] = {0.85f, 0.2f, 0.15f, 1.0f};

static void set_rgba(mjModel *m, int geom, const float rgba[4]) {
  if (geom >= 0) memcpy(m->geom_rgba + 4 * geom, rgba, 4 * sizeof(float));
}

/* The ideal world: the planning model's own scene (sim/nds_model.h) at its defaults. */
static int build_ideal(view_scene *s, char *err, int errlen) {
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  if (nds_model_init(&s->nm, &cfg, err, errlen)) return -1;
  s->m = s->nm.m;
  s->obj_qpos = s->nm.obj_qpos;
  s->ee_qpos[0] = s->nm.ee_qpos[0];
  s->ee_qpos[1] = s->nm.ee_qpos[1];
  s->ee_geom = mj_name2id(s->m, mjOBJ_GEOM, "ee");
  s->ee_radius = cfg.ee_radius;
  s->ee_height = s->nm.ee_height;
  set_rgba(s->m, s->ee_geom, rgba_ee);
  return 0;
}

/* The lab world: the emulated Panda's scene (sim/nds_panda.h) with the lab's box, as the
 * bridge's --world lab preset has them (sim/nds_world.h); the sphere is the arm's tool,
 * posed through the arm's joints. */
static int build_lab(view_scene *s, char *err, int errlen) {
  nds_world_cfg lab;
  nds_world_cfg_lab(&lab);
  const nds_panda_cfg arm = lab.panda;
  nds_scene_cfg obj = lab.object;
  memcpy(obj.theta, lab.theta, sizeof(obj.theta));
  obj.timestep = lab.dt;
  if (!(s->m = nds_panda_scene_load(&arm, &obj, 1, err, errlen)) ||
      nds_panda_resolve(&s->arm, s->m, &arm, err, errlen))
    return -1;
  const int b = mj_name2id(s->m, mjOBJ_BODY, "object");
  const int j = b >= 0 ? s->m->body_jntadr[b] : -1;
  if (j < 0 || s->m->jnt_type[j] != mjJNT_FREE) {
    snprintf(err, errlen, "lab scene: body \"object\" has no free joint");
    return -1;
  }
  s->obj_qpos = s->m->jnt_qposadr[j];
  s->ee_qpos[0] = s->ee_qpos[1] = -1;
  s->ee_geom = -1;
  s->ee_radius = arm.ee_radius;
  s->ee_height = nds_panda_push_height(&arm);
  return 0;
}

int view_scene_init(view_scene *s, int world, int w, int h, int samples, char *err,
                    int errlen) {
  memset(s, 0, sizeof(*s));
  s->world = world;
  if ((world == VIEW_WORLD_LAB ? build_lab : build_ideal)(s, err, errlen)) return -1;
  mjModel *m = s->m;
  s->obj_geom = mj_name2id(m, mjOBJ_GEOM, "object");
  if (s->obj_geom < 0 || m->geom_type[s->obj_geom] != mjGEOM_BOX) {
    snprintf(err, errlen, "scene: no box geom named \"object\"");
    return -1;
  }
  for (int k = 0; k < 3; k++) s->obj_half[k] = m->geom_size[3 * s->obj_geom + k];
  set_rgba(m, s->obj_geom, rgba_object);
  set_rgba(m, mj_name2id(m, mjOBJ_GEOM, "table"), rgba_table);
  /* mjr_makeContext sizes the offscreen buffer from the model. */
  m->vis.global.offwidth = w;
  m->vis.global.offheight = h;
  m->vis.quality.offsamples = samples;
  /* The scene has no light of its own: a brighter, flatter headlight than MuJoCo's default
   * (ambient 0.1, diffuse 0.4) keeps the colours readable from any camera. */
  const float amb[3] = {0.35f, 0.35f, 0.35f}, dif[3] = {0.55f, 0.55f, 0.55f},
              spec[3] = {0.1f, 0.1f, 0.1f};
  memcpy(m->vis.headlight.ambient, amb, sizeof amb);
  memcpy(m->vis.headlight.diffuse, dif, sizeof dif);
  memcpy(m->vis.headlight.specular, spec, sizeof spec);
  if (!(s->d = mj_makeData(m))) {
    snprintf(err, errlen, "scene: out of memory for mjData");
    return -1;
  }
  return 0;
}

void view_scene_pose(view_scene *s, const view_inputs *in) {
  const mjModel *m = s->m;
  mjData *d = s->d;
  if (in->have_mocap) {
    const double *q = in->mocap.obj_quat;
    memcpy(d->qpos + s->obj_qpos, in->mocap.obj_pos, 3 * sizeof(double));
    /* ndp_check_mocap allows 1% off unit norm; the rotation matrix wants it exact. */
    mjtNum u[4] = {q[0], q[1], q[2], q[3]};
    mju_normalize4(u);
    memcpy(d->qpos + s->obj_qpos + 3, u, sizeof u);
    if (s->world == VIEW_WORLD_IDEAL) {
      const int b = s->nm.ee_body;
      for (int k = 0; k < 2; k++)
        d->qpos[s->ee_qpos[k]] =
            in->mocap.ee_pos[k] - m->body_pos[3 * b + k] + m->qpos0[s->ee_qpos[k]];
    }
  }
  if (s->world == VIEW_WORLD_LAB)
    for (int i = 0; i < NDS_PANDA_NJ; i++)
      d->qpos[s->arm.qpos[i]] = in->have_arm ? in->arm_q[i] : s->arm.cfg.q_rest[i];
  mj_kinematics(m, d);
  mj_camlight(m, d);
}

void view_scene_hide_unseen(const view_scene *s, const view_inputs *in, mjvScene *scn) {
  if (in->have_mocap) return;
  int n = 0;
  for (int i = 0; i < scn->ngeom; i++) {
    const mjvGeom *g = &scn->geoms[i];
    const int unseen = g->objid == s->obj_geom || (s->ee_geom >= 0 && g->objid == s->ee_geom);
    if (g->objtype == mjOBJ_GEOM && unseen) continue;
    scn->geoms[n++] = *g;
  }
  scn->ngeom = n;
}

void view_scene_free(view_scene *s) {
  if (s->d) mj_deleteData(s->d);
  if (s->world == VIEW_WORLD_IDEAL) nds_model_free(&s->nm);
  else if (s->m) mj_deleteModel(s->m);
  memset(s, 0, sizeof(*s));
}
