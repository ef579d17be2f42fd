/* nds_model: the pushing scene's MJCF, loading it, and applying theta. */
#include "nds_model.h"

#include "nd_parse.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Where the sphere starts in the generated scene (qpos0), clear of the object at the
 * origin, so qpos0 is a valid non-penetrating configuration for mj_setConst. */
#define NDS_EE_X0 (-0.3)

void nds_scene_cfg_default(nds_scene_cfg *cfg) {
  cfg->obj_half[0] = 0.05;
  cfg->obj_half[1] = 0.03;
  cfg->obj_half[2] = 0.025;
  cfg->obj_mass = 0.5;
  cfg->obj_com[0] = cfg->obj_com[1] = cfg->obj_com[2] = 0.0;
  cfg->solref[0] = 0.02, cfg->solref[1] = 1.0;
  cfg->solimp[0] = 0.9, cfg->solimp[1] = 0.95, cfg->solimp[2] = 0.001;
  cfg->ee_radius = 0.025;
  cfg->timestep = 0.001;
  cfg->condim = 6;
  cfg->tilt_damping = 0.1;
  memcpy(cfg->theta, nd_theta_true, sizeof(cfg->theta));
}

/* What `nudge-calibrate --plan-dt S` prints (its other options at their defaults). */
static const struct {
  double dt, solref[2], solimp[3], tilt_damping;
} plan_contact[] = {{0.01, {0.04191, 0.651}, {0.813, 0.8858, 0.002306}, 0.04021}};

int nds_scene_cfg_planning(nds_scene_cfg *cfg, double dt) {
  nds_scene_cfg_default(cfg);
  cfg->timestep = dt;
  for (size_t i = 0; i < sizeof(plan_contact) / sizeof(plan_contact[0]); i++) {
    if (fabs(dt - plan_contact[i].dt) > 1e-12) continue;
    memcpy(cfg->solref, plan_contact[i].solref, sizeof(cfg->solref));
    memcpy(cfg->solimp, plan_contact[i].solimp, sizeof(cfg->solimp));
    cfg->tilt_damping = plan_contact[i].tilt_damping;
    return 1;
  }
  return 0;
}

static int positive(double v) { return isfinite(v) && v > 0; }

int nds_scene_cfg_check(const nds_scene_cfg *cfg, char *err, int errlen) {
  for (int i = 0; i < 3; i++) {
    if (!positive(cfg->obj_half[i])) {
      snprintf(err, errlen, "scene: obj_half[%d] = %g: must be finite and > 0", i,
               cfg->obj_half[i]);
      return -1;
    }
  }
  if (!positive(cfg->obj_mass)) {
    snprintf(err, errlen, "scene: obj_mass = %g: must be finite and > 0", cfg->obj_mass);
    return -1;
  }
  if (!positive(cfg->ee_radius)) {
    snprintf(err, errlen, "scene: ee_radius = %g: must be finite and > 0", cfg->ee_radius);
    return -1;
  }
  if (!(positive(cfg->timestep) && cfg->timestep <= 0.05)) {
    snprintf(err, errlen, "scene: timestep = %g: must be in (0, 0.05] s", cfg->timestep);
    return -1;
  }
  if (cfg->condim != 3 && cfg->condim != 4 && cfg->condim != 6) {
    snprintf(err, errlen, "scene: condim = %d: must be 3, 4 or 6", cfg->condim);
    return -1;
  }
  for (int i = 0; i < 3; i++)
    if (!(isfinite(cfg->obj_com[i]) && fabs(cfg->obj_com[i]) <= cfg->obj_half[i])) {
      snprintf(err, errlen, "scene: obj_com[%d] = %g: must lie inside the box", i,
               cfg->obj_com[i]);
      return -1;
    }
  if (!(positive(cfg->solref[0]) && positive(cfg->solref[1]) && cfg->solref[0] < 1)) {
    snprintf(err, errlen, "scene: solref %g %g: need a time constant in (0, 1) s and a "
             "damping ratio > 0", cfg->solref[0], cfg->solref[1]);
    return -1;
  }
  if (!(cfg->solimp[0] > 0 && cfg->solimp[0] <= cfg->solimp[1] && cfg->solimp[1] < 1 &&
        positive(cfg->solimp[2]))) {
    snprintf(err, errlen, "scene: solimp %g %g %g: need 0 < d0 <= dwidth < 1 and a width > 0",
             cfg->solimp[0], cfg->solimp[1], cfg->solimp[2]);
    return -1;
  }
  if (!(isfinite(cfg->tilt_damping) && cfg->tilt_damping >= 0)) {
    snprintf(err, errlen, "scene: tilt_damping = %g: must be finite and >= 0",
             cfg->tilt_damping);
    return -1;
  }
  /* The sphere pushes the box only if its centre is below the box's top face. */
  if (cfg->ee_radius + NDS_EE_GAP >= 2 * cfg->obj_half[2]) {
    snprintf(err, errlen,
             "scene: ee_radius = %g: sphere centre (%g m) must be below the object top "
             "(%g m)",
             cfg->ee_radius, cfg->ee_radius + NDS_EE_GAP, 2 * cfg->obj_half[2]);
    return -1;
  }
  return nd_theta_check(cfg->theta, err, errlen);
}

/* Append printf output at buf[*at]. Return 0, or -1 if it does not fit. */
static int put(char *buf, int len, int *at, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static int put(char *buf, int len, int *at, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  const int n = *at < len ? vsnprintf(buf + *at, (size_t)(len - *at), fmt, ap) : -1;
  va_end(ap);
  if (n < 0 || *at + n >= len) return -1;
  *at += n;
  return 0;
}

int nds_scene_xml_head(const nds_scene_cfg *cfg, const char *name, char *buf, int len,
                       int *at) {
  const double *th = cfg->theta;
  return put(buf, len, at,
             "<mujoco model=\"%s\">\n"
             "  <compiler angle=\"radian\"/>\n"
             "  <option timestep=\"%.17g\" integrator=\"Euler\" cone=\"elliptic\" "
             "solver=\"Newton\" iterations=\"%d\" tolerance=\"%g\" noslip_iterations=\"0\"/>\n"
             "  <size nconmax=\"%d\" njmax=\"%d\" nstack=\"%d\"/>\n"
             "  <default>\n"
             "    <geom condim=\"%d\" friction=\"%.17g %.17g %.17g\" solref=\"%.17g %.17g\" "
             "solimp=\"%.17g %.17g %.17g\"/>\n"
             "  </default>\n"
             "  <worldbody>\n"
             "    <geom name=\"table\" type=\"plane\" size=\"1 1 0.05\"/>\n",
             name, cfg->timestep, NDS_ITERATIONS, NDS_TOLERANCE, NDS_NCONMAX,
             NDS_NCONMAX * 6, NDS_NSTACK, cfg->condim, th[ND_TH_SLIDE], th[ND_TH_TORSION],
             th[ND_TH_ROLL], cfg->solref[0], cfg->solref[1], cfg->solimp[0], cfg->solimp[1],
             cfg->solimp[2]);
}

int nds_scene_xml_object(const nds_scene_cfg *cfg, char *buf, int len, int *at) {
  const double *h = cfg->obj_half, *c = cfg->obj_com, m = cfg->obj_mass;
  /* Uniform solid box: I = m/3 (b^2 + c^2) in half sizes, about its centre; an offset
   * centre of mass keeps that tensor (a box with a denser part). */
  return put(buf, len, at,
             "    <body name=\"object\" pos=\"0 0 %.17g\">\n"
             "      <freejoint name=\"object\"/>\n"
             "      <inertial pos=\"%.17g %.17g %.17g\" mass=\"%.17g\" "
             "diaginertia=\"%.17g %.17g %.17g\"/>\n"
             "      <geom name=\"object\" type=\"box\" size=\"%.17g %.17g %.17g\"/>\n"
             "    </body>\n",
             h[2], c[0], c[1], c[2], m, m / 3 * (h[1] * h[1] + h[2] * h[2]),
             m / 3 * (h[0] * h[0] + h[2] * h[2]), m / 3 * (h[0] * h[0] + h[1] * h[1]), h[0],
             h[1], h[2]);
}

int nds_scene_xml(const nds_scene_cfg *cfg, char *buf, int len, char *err, int errlen) {
  if (nds_scene_cfg_check(cfg, err, errlen)) return -1;
  int at = 0;
  const double ee_z = cfg->ee_radius + NDS_EE_GAP;
  if (nds_scene_xml_head(cfg, "nudge_push", buf, len, &at) ||
      nds_scene_xml_object(cfg, buf, len, &at) ||
      put(buf, len, &at,
          "    <body name=\"ee\" pos=\"%.17g 0 %.17g\">\n"
          "      <joint name=\"ee_x\" type=\"slide\" axis=\"1 0 0\" ref=\"%.17g\"/>\n"
          "      <joint name=\"ee_y\" type=\"slide\" axis=\"0 1 0\"/>\n"
          "      <geom name=\"ee\" type=\"sphere\" size=\"%.17g\" mass=\"%.17g\"/>\n"
          "    </body>\n"
          "  </worldbody>\n"
          "  <contact>\n"
          "    <exclude body1=\"world\" body2=\"ee\"/>\n"
          "  </contact>\n"
          "</mujoco>\n",
          NDS_EE_X0, ee_z, NDS_EE_X0, cfg->ee_radius, cfg->theta[ND_TH_MASS])) {
    snprintf(err, errlen, "scene: XML does not fit, buffer has %d bytes", len);
    return -1;
  }
  return 0;
}

/* Find the bodies and joints the rest of sim/ indexes, checking the structure it relies
 * on. `what` names the model's origin in messages. */
static int resolve(nds_model *nm, const char *what, char *err, int errlen) {
  const mjModel *m = nm->m;
  nm->obj_body = mj_name2id(m, mjOBJ_BODY, "object");
  nm->ee_body = mj_name2id(m, mjOBJ_BODY, "ee");
  if (nm->obj_body < 0 || nm->ee_body < 0) {
    snprintf(err, errlen, "%s: no body named \"%s\"", what,
             nm->obj_body < 0 ? "object" : "ee");
    return -1;
  }
  int oj = m->body_jntadr[nm->obj_body];
  if (m->body_jntnum[nm->obj_body] != 1 || m->jnt_type[oj] != mjJNT_FREE) {
    snprintf(err, errlen, "%s: body \"object\" needs exactly one joint, a free joint", what);
    return -1;
  }
  nm->obj_qpos = m->jnt_qposadr[oj];
  nm->obj_dof = m->jnt_dofadr[oj];
  if (m->body_parentid[nm->ee_body] != 0) {
    snprintf(err, errlen, "%s: body \"ee\" must be a child of the world body", what);
    return -1;
  }
  static const char *jname[2] = {"ee_x", "ee_y"};
  for (int k = 0; k < 2; k++) {
    int j = mj_name2id(m, mjOBJ_JOINT, jname[k]);
    if (j < 0) {
      snprintf(err, errlen, "%s: no joint named \"%s\"", what, jname[k]);
      return -1;
    }
    const mjtNum *ax = m->jnt_axis + 3 * j;
    if (m->jnt_type[j] != mjJNT_SLIDE || m->jnt_bodyid[j] != nm->ee_body ||
        fabs(ax[k] - 1) > 1e-9 || fabs(ax[1 - k]) > 1e-9 || fabs(ax[2]) > 1e-9) {
      snprintf(err, errlen, "%s: joint \"%s\" must be a slide joint of body \"ee\" along %c",
               what, jname[k], "xy"[k]);
      return -1;
    }
    nm->ee_qpos[k] = m->jnt_qposadr[j];
    nm->ee_dof[k] = m->jnt_dofadr[j];
  }
  if (m->body_jntnum[nm->ee_body] != 2) {
    snprintf(err, errlen, "%s: body \"ee\" must have only the joints ee_x and ee_y", what);
    return -1;
  }
  /* theta's sphere mass is the mass its two dofs move. */
  for (int b = 0; b < m->nbody; b++) {
    if (m->body_parentid[b] == nm->ee_body && b != nm->ee_body) {
      snprintf(err, errlen, "%s: body \"ee\" must have no child bodies", what);
      return -1;
    }
  }
  nm->ee_height = m->body_pos[3 * nm->ee_body + 2];
  const int b = nm->ee_body, o = nm->obj_body;
  nm->ee_mass0 = m->body_mass[b];
  nm->obj_mass0 = m->body_mass[o];
  for (int k = 0; k < 3; k++) {
    nm->ee_inertia0[k] = m->body_inertia[3 * b + k];
    nm->obj_inertia0[k] = m->body_inertia[3 * o + k];
    nm->obj_ipos0[k] = m->body_ipos[3 * o + k];
  }
  nm->obj_sameframe0 = m->body_sameframe[o];
  nm->obj_simple0 = m->body_simple[o];
  nm->d0 = mj_makeData(m);
  if (!nm->d0) {
    snprintf(err, errlen, "%s: out of memory for the model's scratch data", what);
    return -1;
  }
  return 0;
}

int nds_model_init(nds_model *nm, const nds_scene_cfg *cfg, char *err, int errlen) {
  memset(nm, 0, sizeof(*nm));
  char xml[4096];
  if (nds_scene_xml(cfg, xml, sizeof(xml), err, errlen)) return -1;

  /* The VFS holds mjMAXVFS file names inline (~2 MB): too big for the stack. */
  mjVFS *vfs = malloc(sizeof(mjVFS));
  if (!vfs) {
    snprintf(err, errlen, "scene: out of memory for the VFS");
    return -1;
  }
  mj_defaultVFS(vfs);
  static const char fname[] = "nudge_scene.xml";
  int len = (int)strlen(xml);
  if (mj_makeEmptyFileVFS(vfs, fname, len)) {
    snprintf(err, errlen, "scene: cannot add %s to the VFS", fname);
    free(vfs);
    return -1;
  }
  memcpy(vfs->filedata[mj_findFileVFS(vfs, fname)], xml, len);
  char lerr[512] = "";
  nm->m = mj_loadXML(fname, vfs, lerr, sizeof(lerr));
  mj_deleteVFS(vfs);
  free(vfs);
  if (!nm->m) {
    snprintf(err, errlen, "scene: MuJoCo rejected the generated MJCF: %s", lerr);
    return -1;
  }
  nm->cfg = *cfg;
  if (resolve(nm, "scene", err, errlen) || nds_theta_apply(nm, cfg->theta, err, errlen)) {
    nds_model_free(nm);
    return -1;
  }
  /* Free-joint angular velocity is in the body frame: dofs 3 and 4 are roll and pitch
   * while the box is upright, dof 5 its yaw, which stays undamped. */
  nm->m->dof_damping[nm->obj_dof + 3] = cfg->tilt_damping;
  nm->m->dof_damping[nm->obj_dof + 4] = cfg->tilt_damping;
  return 0;
}

int nds_model_load_file(nds_model *nm, const char *path, const nds_scene_cfg *cfg,
                        char *err, int errlen) {
  memset(nm, 0, sizeof(*nm));
  if (nd_theta_check(cfg->theta, err, errlen)) return -1;
  char lerr[512] = "";
  nm->m = mj_loadXML(path, NULL, lerr, sizeof(lerr));
  if (!nm->m) {
    snprintf(err, errlen, "%s: %s", path, lerr[0] ? lerr : "cannot load");
    return -1;
  }
  if (resolve(nm, path, err, errlen)) {
    nds_model_free(nm);
    return -1;
  }
  /* cfg records what the file describes, where it says it, so state helpers (e.g. the
   * resting height) follow the file rather than the defaults. */
  const mjModel *m = nm->m;
  nm->cfg = *cfg;
  nm->cfg.timestep = m->opt.timestep;
  nm->cfg.obj_mass = m->body_mass[nm->obj_body];
  nm->cfg.tilt_damping = m->dof_damping[nm->obj_dof + 3];
  for (int g = 0; g < m->ngeom; g++) {
    if (m->geom_bodyid[g] == nm->obj_body && m->geom_type[g] == mjGEOM_BOX) {
      memcpy(nm->cfg.obj_half, m->geom_size + 3 * g, sizeof(nm->cfg.obj_half));
      nm->cfg.condim = m->geom_condim[g];
    }
    if (m->geom_bodyid[g] == nm->ee_body && m->geom_type[g] == mjGEOM_SPHERE)
      nm->cfg.ee_radius = m->geom_size[3 * g];
  }
  if (nds_theta_apply(nm, cfg->theta, err, errlen)) {
    nds_model_free(nm);
    return -1;
  }
  return 0;
}

int nds_model_copy(nds_model *dst, const nds_model *src, char *err, int errlen) {
  *dst = *src;
  dst->d0 = NULL;
  dst->m = mj_copyModel(NULL, src->m);
  if (dst->m) dst->d0 = mj_makeData(dst->m);
  if (!dst->m || !dst->d0) {
    nds_model_free(dst);
    snprintf(err, errlen, "model copy: out of memory");
    return -1;
  }
  return 0;
}

void nds_model_free(nds_model *nm) {
  if (nm->d0) mj_deleteData(nm->d0);
  if (nm->m) mj_deleteModel(nm->m);
  nm->d0 = NULL;
  nm->m = NULL;
}

/* MuJoCo's compiler marks a body whose inertial frame is its own frame (sameframe) and,
 * if its joints allow, one whose dofs have a diagonal mass matrix (simple, and
 * dof_simplenum, the simple dofs that follow each dof), and takes the fast path for them.
 * A box with its centre of mass moved off the origin (shifted 1) has neither: the general
 * path, which is exact for any body. Unshifted, the flags are as loaded, so the bits are
 * those of the model as built. Geoms and sites placed at the inertial frame (sameframe 2)
 * would move with it; they get the general path too, and back when unshifted: the
 * compiler marks exactly those whose pose is the inertial frame's as loaded. */
/* A box geom's or site's sameframe flag for the box shifted or not (set_frames). */
static mjtByte sameframe(const nds_model *nm, mjtByte flag, const mjtNum pos[3],
                         const mjtNum quat[4], int shifted) {
  const mjtNum *iq = nm->m->body_iquat + 4 * nm->obj_body;
  if (shifted) return flag == 2 ? 0 : flag;
  const int at_iframe = pos[0] == nm->obj_ipos0[0] && pos[1] == nm->obj_ipos0[1] &&
                        pos[2] == nm->obj_ipos0[2] && quat[0] == iq[0] && quat[1] == iq[1] &&
                        quat[2] == iq[2] && quat[3] == iq[3];
  return flag == 0 && at_iframe ? 2 : flag;
}

static void set_frames(nds_model *nm, int shifted) {
  mjModel *m = nm->m;
  const int o = nm->obj_body, d0 = m->body_dofadr[o], nd = m->body_dofnum[o];
  m->body_sameframe[o] = shifted ? 0 : nm->obj_sameframe0;
  m->body_simple[o] = shifted ? 0 : nm->obj_simple0;
  /* dof_simplenum counts down along a run of simple dofs; recount every run. */
  for (int i = m->nv - 1; i >= 0; i--) {
    const int b = m->dof_bodyid[i];
    const int simple = m->body_simple[b] && !(shifted && i >= d0 && i < d0 + nd);
    m->dof_simplenum[i] = simple ? 1 + (i + 1 < m->nv ? m->dof_simplenum[i + 1] : 0) : 0;
  }
  for (int g = 0; g < m->ngeom; g++)
    if (m->geom_bodyid[g] == o)
      m->geom_sameframe[g] = sameframe(nm, m->geom_sameframe[g], m->geom_pos + 3 * g,
                                       m->geom_quat + 4 * g, shifted);
  for (int s = 0; s < m->nsite; s++)
    if (m->site_bodyid[s] == o)
      m->site_sameframe[s] = sameframe(nm, m->site_sameframe[s], m->site_pos + 3 * s,
                                       m->site_quat + 4 * s, shifted);
}

int nds_theta_apply(nds_model *nm, const double theta[ND_NTHETA], char *err, int errlen) {
  if (nd_theta_check(theta, err, errlen)) return -1;
  mjModel *m = nm->m;

  /* The box's centre of mass must stay inside it, which a model's box may be smaller
   * than ND_THETA_COM_MAX allows. Checked first: a refused theta changes nothing. */
  const int o = nm->obj_body, b = nm->ee_body;
  const double shift[2] = {theta[ND_TH_COM_X], theta[ND_TH_COM_Y]};
  for (int k = 0; k < 2; k++) {
    const double c = nm->obj_ipos0[k] + shift[k];
    if (fabs(c) > nm->cfg.obj_half[k]) {
      snprintf(err, errlen, "theta[%d] (%s) = %g puts the centre of mass at %g m, outside "
               "the box (half side %g m)", ND_TH_COM_X + k, nd_theta_name[ND_TH_COM_X + k],
               shift[k], c, nm->cfg.obj_half[k]);
      return -1;
    }
  }

  /* Every geom gets theta: contacts combine friction by maximum, so each contact sees
   * theta exactly whichever pair it joins. */
  for (int g = 0; g < m->ngeom; g++) {
    m->geom_friction[3 * g + 0] = theta[ND_TH_SLIDE];
    m->geom_friction[3 * g + 1] = theta[ND_TH_TORSION];
    m->geom_friction[3 * g + 2] = theta[ND_TH_ROLL];
  }

  /* Scaled from the values as loaded, not from the current ones: repeated applications
   * would otherwise accumulate rounding and theta would not fix the model's bits. An
   * offset centre of mass keeps the inertia about it (a box with a denser part). */
  const double s = theta[ND_TH_MASS] / nm->ee_mass0, f = theta[ND_TH_BOX_SCALE];
  m->body_mass[b] = theta[ND_TH_MASS];
  m->body_mass[o] = nm->obj_mass0 * f;
  for (int k = 0; k < 3; k++) {
    m->body_inertia[3 * b + k] = nm->ee_inertia0[k] * s;
    m->body_inertia[3 * o + k] = nm->obj_inertia0[k] * f;
    m->body_ipos[3 * o + k] = nm->obj_ipos0[k] + (k < 2 ? shift[k] : 0.0);
  }

  set_frames(nm, shift[0] != 0 || shift[1] != 0);

  /* What MuJoCo's compiler derives from the masses (subtree masses, the inverse weights
   * that scale contact softness, the mass matrix at qpos0), derived the same way: a model
   * given theta equals one built with it. */
  mj_setConst(m, nm->d0);
  memcpy(nm->cfg.theta, theta, sizeof(nm->cfg.theta));
  return 0;
}

void nds_contacts(const nds_model *nm, const mjData *d, int *obj_table, int *obj_ee) {
  const mjModel *m = nm->m;
  int nt = 0, ne = 0;
  for (int c = 0; c < d->ncon; c++) {
    /* Contacts the solver ignores (MuJoCo's gap zone) exert nothing: skip them. */
    if (d->contact[c].exclude) continue;
    int b1 = m->geom_bodyid[d->contact[c].geom1], b2 = m->geom_bodyid[d->contact[c].geom2];
    if (b1 != nm->obj_body && b2 != nm->obj_body) continue;
    int other = b1 == nm->obj_body ? b2 : b1;
    nt += other == 0;
    ne += other == nm->ee_body;
  }
  *obj_table = nt;
  *obj_ee = ne;
}
