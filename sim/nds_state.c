/* nds_state: world state <-> mjData, without whole-mjData copies. */
#include "nds_state.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_math.h"

/* A slide joint moves its body by (qpos - qpos0) along its axis from the body's rest
 * position, so the sphere's world (x, y) is qpos plus this offset (0 in the generated
 * scene, whose joint refs equal the body position). */
static double ee_offset(const nds_model *nm, int k) {
  const mjModel *m = nm->m;
  return m->body_pos[3 * nm->ee_body + k] - m->qpos0[nm->ee_qpos[k]];
}

void nds_state_get(const nds_model *nm, const mjData *d, nds_state *s) {
  const mjtNum *q = d->qpos + nm->obj_qpos, *v = d->qvel + nm->obj_dof;
  memcpy(s->obj_pos, q, 3 * sizeof(double));
  memcpy(s->obj_quat, q + 3, 4 * sizeof(double));
  memcpy(s->obj_vel, v, 6 * sizeof(double));
  for (int k = 0; k < 2; k++) {
    s->ee_pos[k] = d->qpos[nm->ee_qpos[k]] + ee_offset(nm, k);
    s->ee_vel[k] = d->qvel[nm->ee_dof[k]];
  }
}

int nds_state_set(const nds_model *nm, mjData *d, const nds_state *s, char *err, int errlen) {
  const mjModel *m = nm->m;
  if (!nd_all_finite(s->obj_pos, 3) || !nd_all_finite(s->obj_quat, 4) ||
      !nd_all_finite(s->obj_vel, 6) || !nd_all_finite(s->ee_pos, 2) ||
      !nd_all_finite(s->ee_vel, 2)) {
    snprintf(err, errlen, "state: not finite");
    return -1;
  }
  const double *qt = s->obj_quat;
  double qn = sqrt(qt[0] * qt[0] + qt[1] * qt[1] + qt[2] * qt[2] + qt[3] * qt[3]);
  if (!(qn > 1e-12)) {
    snprintf(err, errlen, "state: object quaternion has zero norm");
    return -1;
  }

  /* Everything mj_step reads besides the model: configuration, velocity and every input,
   * plus the solver's warm start. Writing them all makes the next step a function of s
   * alone, whatever ran on d before. Dofs the state does not cover (a user model's extra
   * joints) start at qpos0 and rest. */
  mju_copy(d->qpos, m->qpos0, m->nq);
  mju_zero(d->qvel, m->nv);
  mjtNum *q = d->qpos + nm->obj_qpos;
  for (int i = 0; i < 3; i++) q[i] = s->obj_pos[i];
  for (int i = 0; i < 4; i++) q[3 + i] = qt[i] / qn;
  mju_copy(d->qvel + nm->obj_dof, s->obj_vel, 6);
  for (int k = 0; k < 2; k++) {
    d->qpos[nm->ee_qpos[k]] = s->ee_pos[k] - ee_offset(nm, k);
    d->qvel[nm->ee_dof[k]] = s->ee_vel[k];
  }
  d->time = 0;
  mju_zero(d->qacc_warmstart, m->nv);
  mju_zero(d->qacc, m->nv);
  mju_zero(d->qfrc_applied, m->nv);
  mju_zero(d->xfrc_applied, 6 * m->nbody);
  mju_zero(d->act, m->na);
  mju_zero(d->ctrl, m->nu);
  mju_zero(d->userdata, m->nuserdata);
  for (int i = 0; i < m->nbody; i++) {
    int id = m->body_mocapid[i];
    if (id >= 0) {
      mju_copy3(d->mocap_pos + 3 * id, m->body_pos + 3 * i);
      mju_copy4(d->mocap_quat + 4 * id, m->body_quat + 4 * i);
    }
  }
  return 0;
}

void nds_state_rest(const nds_model *nm, double x, double y, double yaw, const double ee[2],
                    nds_state *s) {
  memset(s, 0, sizeof(*s));
  s->obj_pos[0] = x;
  s->obj_pos[1] = y;
  s->obj_pos[2] = nm->cfg.obj_half[2];
  nd_yaw_quat(yaw, s->obj_quat);
  s->ee_pos[0] = ee[0];
  s->ee_pos[1] = ee[1];
}

double nds_state_yaw(const nds_state *s) { return nd_quat_yaw(s->obj_quat); }
