/* test_panda: the emulated Panda's model, kinematics, IK, control and reflexes. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "nd_exec.h"
#include "nd_math.h"
#include "nd_snap.h"
#include "nd_test.h"
#include "nds_panda.h"
#include "nds_reach.h"

#define NJ NDS_PANDA_NJ
#define DT 0.001

/* Franka's "ready" posture: the IK seed the default rest posture came from. */
static const double ready[NJ] = {0, -0.78539816, 0, -2.35619449, 0, 1.57079633, 0.78539816};

#define assert_contains(s, sub)                                                       \
  do {                                                                                \
    if (!strstr((s), (sub))) fail_msg("\"%s\" does not mention \"%s\"", (s), (sub)); \
  } while (0)

/* A loaded scene with the arm resolved and at its rest posture. */
typedef struct {
  nds_panda_cfg cfg;
  mjModel *m;
  mjData *d;
  nds_panda p;
} world;

static void world_open(world *w, int with_box) {
  char err[512] = "";
  nds_panda_cfg_default(&w->cfg);
  w->m = nds_panda_scene_load(&w->cfg, NULL, with_box, err, sizeof(err));
  if (!w->m) fail_msg("scene: %s", err);
  if (nds_panda_resolve(&w->p, w->m, &w->cfg, err, sizeof(err)))
    fail_msg("resolve: %s", err);
  w->d = mj_makeData(w->m);
  assert_non_null(w->d);
  nds_panda_set_q(&w->p, w->m, w->d, w->cfg.q_rest);
}

static void world_close(world *w) {
  mj_deleteData(w->d);
  mj_deleteModel(w->m);
}

/* Deterministic uniform numbers in [0, 1) (64-bit LCG, top 53 bits). */
static double uniform(uint64_t *s) {
  *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
  return (double)(*s >> 11) / 9007199254740992.0;
}

static double dist3(const double *a, const double *b) {
  return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
              (a[2] - b[2]) * (a[2] - b[2]));
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}

/* ---- model ---- */

static void test_model_structure(void **state) {
  (void)state;
  world w;
  world_open(&w, 1);
  const mjModel *m = w.m;
  assert_int_equal(m->nu, NJ);
  assert_int_equal(m->nv, NJ + 6);
  assert_near(m->opt.timestep, DT, 0);
  assert_int_equal(m->opt.integrator, mjINT_EULER);
  for (int i = 0; i < NJ; i++) {
    int j = m->dof_jntid[w.p.dof[i]];
    assert_near(m->jnt_range[2 * j], nds_panda_q_min[i], 0);
    assert_near(m->jnt_range[2 * j + 1], nds_panda_q_max[i], 0);
    assert_near(m->actuator_ctrlrange[2 * w.p.act[i] + 1], nds_panda_tau_max[i], 0);
    assert_true(m->jnt_limited[j]);
  }
  /* Gaz et al., supplementary Table VIII: 16.062132 kg of links, plus the tool. */
  double mass = 0;
  for (int i = 1; i <= NJ; i++) mass += m->body_mass[w.p.body[i]];
  assert_near(mass, 16.062132, 1e-9);
  assert_near(m->body_mass[w.p.body_tool], w.cfg.tool_mass, 1e-12);
  /* Link 4's centre of mass (Table VIII) and its inertia about it (Table IX) in DH frame
   * 4: rebuilt from MuJoCo's principal axes, the tensor must be the published one, which
   * checks the fullinertia ordering (xx yy zz xy xz yz against the table's xx xy xz yy yz
   * zz) and that the body frame is the DH frame. */
  int b = w.p.body[4];
  assert_near(m->body_ipos[3 * b + 0], -5.317e-02, 1e-12);
  assert_near(m->body_ipos[3 * b + 1], 1.04419e-01, 1e-12);
  assert_near(m->body_ipos[3 * b + 2], 2.7454e-02, 1e-12);
  double R[9], I[9];
  mju_quat2Mat(R, m->body_iquat + 4 * b);
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) {
      I[3 * r + c] = 0;
      for (int k = 0; k < 3; k++)
        I[3 * r + c] += R[3 * r + k] * m->body_inertia[3 * b + k] * R[3 * c + k];
    }
  const double gaz4[9] = {2.5853e-02,  7.7960e-03, -1.3320e-03, 7.7960e-03, 1.9552e-02,
                          8.6410e-03, -1.3320e-03, 8.6410e-03,  2.8323e-02};
  for (int k = 0; k < 9; k++) assert_near(I[k], gaz4[k], 1e-7); /* mju_eig3's precision */
  /* Only the sphere collides; the sphere-world pair is excluded. */
  for (int g = 0; g < m->ngeom; g++) {
    int arm = m->geom_bodyid[g] >= w.p.body[0];
    if (arm && g != w.p.geom_sphere) {
      assert_int_equal(m->geom_contype[g], 0);
      assert_int_equal(m->geom_conaffinity[g], 0);
    }
  }
  assert_int_equal(m->geom_contype[w.p.geom_sphere], 1);
  assert_near(m->geom_size[3 * w.p.geom_sphere], w.cfg.ee_radius, 0);
  /* A cfg that is not the model's arm is refused. */
  char err[256] = "";
  nds_panda_cfg other = w.cfg;
  nds_panda p2;
  other.tool_length = 0.15;
  assert_int_equal(nds_panda_resolve(&p2, m, &other, err, sizeof(err)), -1);
  assert_contains(err, "away from cfg");
  world_close(&w);
}

/* A controller sized for one model refuses another's mjData rather than overrun. */
static void test_ctrl_model_mismatch(void **state) {
  (void)state;
  world a, b;
  world_open(&a, 1);
  world_open(&b, 0);
  char err[256] = "";
  nds_panda_gains g;
  nds_panda_gains_default(&g);
  nds_panda_ctrl c;
  if (nds_panda_ctrl_init(&c, a.m, &g, err, sizeof(err))) fail_msg("%s", err);
  double p[3] = {-0.1, 0, 0.026}, v[3] = {0, 0, 0}, tau[NJ];
  mj_forward(b.m, b.d);
  assert_int_equal(nds_panda_ctrl_impedance(&c, &b.p, b.m, b.d, p, v, NULL, tau), -1);
  for (int i = 0; i < NJ; i++) assert_near(tau[i], b.d->qfrc_bias[b.p.dof[i]], 0);
  mj_forward(a.m, a.d);
  assert_int_equal(nds_panda_ctrl_impedance(&c, &a.p, a.m, a.d, p, v, NULL, tau), 0);
  nds_panda_ctrl_free(&c);
  g.k_t = -1;
  assert_int_equal(nds_panda_ctrl_init(&c, a.m, &g, err, sizeof(err)), -1);
  assert_contains(err, "gain k_t = -1");
  nds_panda_ctrl_free(&c); /* harmless on a refused one */
  world_close(&a);
  world_close(&b);
}

/* The pieces an integrator drops into its own scene load and resolve, under a <default>
 * of its own; without the <exclude>, resolve refuses. */
static void test_xml_pieces(void **state) {
  (void)state;
  nds_panda_cfg cfg;
  nds_panda_cfg_default(&cfg);
  char body[8192], contact[512], act[2048], err[256] = "", xml[16384];
  assert_int_equal(nds_panda_xml_body(&cfg, body, sizeof(body), err, sizeof(err)), 0);
  assert_int_equal(nds_panda_xml_contact(contact, sizeof(contact), err, sizeof(err)), 0);
  assert_int_equal(nds_panda_xml_actuator(act, sizeof(act), err, sizeof(err)), 0);
  assert_contains(contact, "body2=\"panda_tool\"");
  char small[100];
  assert_int_equal(nds_panda_xml_body(&cfg, small, sizeof(small), err, sizeof(err)), -1);
  assert_contains(err, "buffer has 100");

  for (int with_exclude = 1; with_exclude >= 0; with_exclude--) {
    snprintf(xml, sizeof(xml),
             "<mujoco><default><geom condim=\"4\"/><joint damping=\"5\"/></default>"
             "<worldbody><geom name=\"table\" type=\"plane\" size=\"1 1 .1\"/>"
             "%s</worldbody>"
             "<contact>%s</contact><actuator>%s</actuator></mujoco>",
             body, with_exclude ? contact : "", act);
    char lerr[512] = "";
    mjVFS *vfs = malloc(sizeof(mjVFS));
    assert_non_null(vfs);
    mj_defaultVFS(vfs);
    assert_int_equal(mj_makeEmptyFileVFS(vfs, "s.xml", (int)strlen(xml)), 0);
    memcpy(vfs->filedata[mj_findFileVFS(vfs, "s.xml")], xml, strlen(xml));
    mjModel *m = mj_loadXML("s.xml", vfs, lerr, sizeof(lerr));
    mj_deleteVFS(vfs);
    free(vfs);
    if (!m) fail_msg("load: %s", lerr);
    nds_panda p;
    int rc = nds_panda_resolve(&p, m, &cfg, err, sizeof(err));
    if (with_exclude) {
      if (rc) fail_msg("resolve: %s", err);
      /* The pieces state their joint properties, so the scene's default is not taken. */
      assert_near(m->dof_damping[p.dof[3]], 0.1, 0);
    } else {
      assert_int_equal(rc, -1);
      assert_contains(err, "exclude");
    }
    mj_deleteModel(m);
  }
}

static void test_cfg_check(void **state) {
  (void)state;
  nds_panda_cfg c0, c;
  char err[256] = "";
  nds_panda_cfg_default(&c0);
  assert_int_equal(nds_panda_cfg_check(&c0, err, sizeof(err)), 0);
  c = c0, c.ee_radius = 0;
  assert_int_equal(nds_panda_cfg_check(&c, err, sizeof(err)), -1);
  assert_contains(err, "ee_radius");
  c = c0, c.tool_length = 0.04;
  assert_int_equal(nds_panda_cfg_check(&c, err, sizeof(err)), -1);
  assert_contains(err, "tool_length");
  c = c0, c.q_rest[3] = 0;
  assert_int_equal(nds_panda_cfg_check(&c, err, sizeof(err)), -1);
  assert_contains(err, "joint 4");
  c = c0, c.base_pos[2] = NAN;
  assert_int_equal(nds_panda_cfg_check(&c, err, sizeof(err)), -1);
  assert_near(nds_panda_push_height(&c0), 0.026, 1e-15);
}

/* ---- kinematics ---- */

/* The plain-C DH kinematics against MuJoCo's bodies and sites, on random postures within
 * the limits, for the default base and for a moved, yawed one. */
static void test_fk_matches_mujoco(void **state) {
  (void)state;
  for (int variant = 0; variant < 2; variant++) {
    char err[512] = "";
    nds_panda_cfg cfg;
    nds_panda_cfg_default(&cfg);
    if (variant) {
      cfg.base_pos[0] = 0.3, cfg.base_pos[1] = -0.7, cfg.base_pos[2] = 0.1;
      cfg.base_yaw = 2.1, cfg.tool_length = 0.12;
    }
    mjModel *m = nds_panda_scene_load(&cfg, NULL, 0, err, sizeof(err));
    if (!m) fail_msg("%s", err);
    nds_panda p;
    if (nds_panda_resolve(&p, m, &cfg, err, sizeof(err))) fail_msg("%s", err);
    mjData *d = mj_makeData(m);
    mjtNum jacp[3 * NJ], jacr[3 * NJ];
    uint64_t seed = 12345 + variant;
    double worst_p = 0, worst_r = 0, worst_j = 0;
    for (int n = 0; n < 300; n++) {
      double q[NJ], fpos[3], fR[9], tool[3], J[35];
      for (int i = 0; i < NJ; i++)
        q[i] = nds_panda_q_min[i] +
               (nds_panda_q_max[i] - nds_panda_q_min[i]) * uniform(&seed);
      for (int i = 0; i < NJ; i++) d->qpos[p.qpos[i]] = q[i];
      mj_kinematics(m, d);
      mj_comPos(m, d);
      nds_panda_fk(&cfg, q, fpos, fR, tool);
      worst_p = fmax(worst_p, dist3(fpos, d->site_xpos + 3 * p.site_flange));
      worst_p = fmax(worst_p, dist3(tool, d->site_xpos + 3 * p.site_tool));
      for (int k = 0; k < 9; k++)
        worst_r = fmax(worst_r, fabs(fR[k] - d->site_xmat[9 * p.site_flange + k]));
      /* Link 4's body frame is DH frame 4: its origin is joint 4's, on its axis. */
      nds_panda_jac(&cfg, q, J);
      mj_jacSite(m, d, jacp, jacr, p.site_tool);
      for (int i = 0; i < NJ; i++) {
        for (int r = 0; r < 3; r++)
          worst_j = fmax(worst_j, fabs(J[r * NJ + i] - jacp[r * m->nv + p.dof[i]]));
        for (int r = 0; r < 2; r++)
          worst_j = fmax(worst_j, fabs(J[(3 + r) * NJ + i] - jacr[r * m->nv + p.dof[i]]));
      }
    }
    assert_near(worst_p, 0, 1e-9);
    assert_near(worst_r, 0, 1e-9);
    assert_near(worst_j, 0, 1e-9);
    mj_deleteData(d);
    mj_deleteModel(m);
  }
}

/* Every point of the workspace on a 5 cm grid: an IK solution with the tool down, inside
 * the joint margins, from which 0.5 m/s and 2 m/s^2 stay within the joint limits. */
static void test_ik_workspace_grid(void **state) {
  (void)state;
  nds_panda_cfg cfg;
  nds_panda_cfg_default(&cfg);
  const double z = nds_panda_push_height(&cfg);
  char err[256] = "";
  double q[NJ], tool[3], R[9];
  /* The rest posture is the sphere's start pose, and IK from "ready" finds it again. */
  double start[3] = {-0.10, 0, z};
  assert_int_equal(nds_panda_ik(&cfg, start, ready, q, err, sizeof(err)), 0);
  for (int i = 0; i < NJ; i++) assert_near(q[i], cfg.q_rest[i], 1e-4);
  int n = 0;
  double worst_v = 0, worst_a = 0;
  for (double x = NDS_PANDA_WS_XMIN; x <= NDS_PANDA_WS_XMAX + 1e-9; x += 0.05) {
    for (double y = NDS_PANDA_WS_YMIN; y <= NDS_PANDA_WS_YMAX + 1e-9; y += 0.05) {
      double t[3] = {x, y, z};
      if (nds_panda_ik(&cfg, t, NULL, q, err, sizeof(err))) fail_msg("%s", err);
      nds_panda_fk(&cfg, q, NULL, R, tool);
      assert_near(dist3(tool, t), 0, 1e-8);
      assert_near(R[8], -1, 1e-12); /* tool axis straight down */
      for (int i = 0; i < NJ; i++) {
        assert_true(q[i] >= nds_panda_q_min[i] + NDS_PANDA_IK_MARGIN);
        assert_true(q[i] <= nds_panda_q_max[i] - NDS_PANDA_IK_MARGIN);
      }
      worst_v = fmax(worst_v, nds_panda_speed_ratio(&cfg, q, NDS_PANDA_WS_SPEED));
      worst_a = fmax(worst_a, nds_panda_accel_ratio(&cfg, q, NDS_PANDA_WS_ACCEL));
      n++;
    }
  }
  assert_int_equal(n, 7 * 15);
  print_message("workspace: worst speed ratio %.3f, worst accel ratio %.3f\n", worst_v,
                worst_a);
  assert_true(worst_v <= NDS_PANDA_WS_SPEED_RATIO);
  assert_true(worst_a <= 1.0);

  /* Out of reach, and too close to the base for the joint margins. */
  double far[3] = {0.8, 0, z}, near[3] = {-0.30, 0.05, z};
  assert_int_equal(nds_panda_ik(&cfg, far, NULL, q, err, sizeof(err)), -1);
  assert_contains(err, "unreachable");
  assert_int_equal(nds_panda_ik(&cfg, near, NULL, q, err, sizeof(err)), -1);
  assert_contains(err, "IK: (-0.300");
}

/* Why the lab's Cartesian caps may exceed what every direction allows (nudge-up's
 * LAB_PLAN_A 2.5 m/s^2 at LAB_ARM_LOAD 0.9, decisions#lab-caps): from rest, across the
 * arm's reach (y) the joints take 2.5 m/s^2 within 0.9 of their limits at most points of
 * the lab box, radially (x) at few; the planner's arm map tells the two apart per plan. */
static void test_reach_lab_caps(void **state) {
  (void)state;
  nds_reach r;
  char err[256];
  const double lo[2] = {NDS_PANDA_WS_XMIN, NDS_PANDA_WS_YMIN},
               hi[2] = {NDS_PANDA_WS_XMAX, NDS_PANDA_WS_YMAX}, zero[2] = {0.0, 0.0};
  if (nds_reach_build_ws(&r, lo, hi, err, sizeof err)) fail_msg("%s", err);
  int n = 0, ok_x = 0, ok_y = 0;
  for (double x = lo[0]; x <= hi[0] + 1e-9; x += 0.05)
    for (double y = lo[1]; y <= hi[1] + 1e-9; y += 0.05) {
      const double p[2] = {x, y};
      n++;
      ok_x += nds_reach_load(&r, p, zero, (const double[2]){2.5, 0.0}) <= 0.9;
      ok_y += nds_reach_load(&r, p, zero, (const double[2]){0.0, 2.5}) <= 0.9;
    }
  print_message("reach_lab_caps: 2.5 m/s^2 from rest within 0.9 of the joint limits along x at "
                "%d, along y at %d of %d points\n", ok_x, ok_y, n);
  assert_true(2 * ok_y > n);
  assert_true(2 * ok_x < n);
  nds_reach_free(&r);
}

/* The largest arm load (nds_reach_load) over the brakes to rest an executor with cfg takes
 * when its plans stop coming: segments through the points of a 4 cm grid over the lab box,
 * along +-x and +-y at 0.2-0.6 m/s, stale where the sphere passes the point; *over counts
 * the brakes beyond a joint limit. Only the brake is scored: its segment is the planner's,
 * checked against the arm there. */
static double stale_brake_load(const nds_reach *r, const nd_exec_cfg *cfg, int *over, int *n) {
  const double dirs[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  double worst = 0.0;
  char err[256];
  *over = *n = 0;
  for (double x = -0.12; x <= 0.12 + 1e-9; x += 0.04)
    for (double y = -0.26; y <= 0.36 + 1e-9; y += 0.04)
      for (int d = 0; d < 4; d++)
        for (double v = 0.2; v <= 0.6 + 1e-9; v += 0.2) {
          const double u[2] = {dirs[d][0], dirs[d][1]};
          const double p0[2] = {x - 0.1 * u[0], y - 0.1 * u[1]};
          const double key[4] = {x + 0.1 * u[0], y + 0.1 * u[1], v * u[0], v * u[1]};
          nd_exec ex;
          nd_exec_init(&ex, p0, 0.0);
          if (nd_exec_keys_check(cfg, (const double(*)[4])key, 1, NULL, 0) != ND_EXEC_OK ||
              nd_exec_keys_check(cfg, (const double(*)[4])p0, 1, NULL, 0) != ND_EXEC_OK ||
              nd_exec_plan(&ex, cfg, 0.0, key, 0.6, err, sizeof err) != ND_EXEC_OK)
            continue;
          double sp[2][4], t_stale = 0.0, nearest = INFINITY;
          for (double t = 0.0; t < ex.seg.T; t += 1e-3) {
            nd_exec_eval(&ex, t, sp);
            const double dist = hypot(sp[0][ND_P] - x, sp[1][ND_P] - y);
            if (dist < nearest) nearest = dist, t_stale = t;
          }
          double load = 0.0;
          for (double t = 0.0; t <= t_stale + 2.0; t += 1e-3) {
            const int mode = nd_exec_step(&ex, cfg, t, t >= t_stale, sp);
            if (t >= t_stale && t >= ex.t_brake) {
              const double p[2] = {sp[0][ND_P], sp[1][ND_P]}, vel[2] = {sp[0][ND_V], sp[1][ND_V]},
                           acc[2] = {sp[0][ND_A], sp[1][ND_A]};
              load = fmax(load, nds_reach_load(r, p, vel, acc));
            }
            if (mode == ND_EXEC_HOLD) break;
          }
          (*n)++;
          *over += load > 1.0;
          worst = fmax(worst, load);
        }
  return worst;
}

/* The lab executor's stale brakes keep to the arm's joint limits (nudge-up's LAB_EXEC_V
 * 0.65 m/s, LAB_EXEC_A 2.8 m/s^2, LAB_EXEC_BRAKE_A 2.0 m/s^2; decisions#brake-cap): at the
 * Cartesian a_max a radial brake from 0.6 m/s loads joint 2 past its acceleration limit,
 * at the cap none does (near the box's wall the brake planned at a_max, the one inside its
 * margin, comes nearest). */
static void test_stale_brake_lab(void **state) {
  (void)state;
  nds_reach r;
  char err[256];
  const double lo[2] = {NDS_PANDA_WS_XMIN, NDS_PANDA_WS_YMIN},
               hi[2] = {NDS_PANDA_WS_XMAX, NDS_PANDA_WS_YMAX};
  if (nds_reach_build_ws(&r, lo, hi, err, sizeof err)) fail_msg("%s", err);
  nd_exec_cfg cfg = nd_exec_cfg_default();
  cfg.v_max = 0.65, cfg.a_max = 2.8;
  for (int k = 0; k < 2; k++) cfg.ws_lo[k] = lo[k], cfg.ws_hi[k] = hi[k];
  int over, n;
  const double uncapped = stale_brake_load(&r, &cfg, &over, &n);
  print_message("stale_brake_lab: brakes at a_max 2.8: %d of %d beyond a joint limit, worst "
                "load %.3f\n", over, n, uncapped);
  assert_true(over > 0 && uncapped > 1.2);
  cfg.brake_a_max = 2.0;
  const double capped = stale_brake_load(&r, &cfg, &over, &n);
  print_message("stale_brake_lab: brakes at 2.0: %d of %d beyond, worst load %.3f\n", over, n,
                capped);
  assert_true(n > 500);
  assert_int_equal(over, 0);
  assert_true(capped <= 1.0);
  nds_reach_free(&r);
}

/* The reach map agrees with IK at points between its nodes in every direction, its joint
 * accelerations at speed with IK's second differences along the path (the velocity-product
 * terms), serves the lab box at the lab's 0.5 m/s, tells radial from cross motion, shows
 * where beyond the box the arm cannot go that fast, and is infinite where there is no IK or
 * no map. */
static void test_reach_map(void **state) {
  (void)state;
  nds_panda_cfg cfg;
  nds_panda_cfg_default(&cfg);
  const double z = nds_panda_push_height(&cfg);
  const double lo[2] = {-0.30, -0.45}, hi[2] = {0.30, 0.55};
  nds_reach r;
  char err[256] = "";
  if (nds_reach_build(&r, &cfg, lo, hi, 0.02, err, sizeof err)) fail_msg("%s", err);
  assert_int_equal(r.nx, 31);
  assert_int_equal(r.ny, 51);
  double worst_rel = 0.0, lab_worst = 0.0, spread = 1.0, vp_max = 0.0;
  double vp_err = 0.0, vp_err_self = 0.0;  /* joints 2 and 4 (pitch), the others */
  double q[NJ], m[NJ][2];
  const double zero[2] = {0.0, 0.0}, S = NDS_PANDA_WS_SPEED;
  for (double x = NDS_PANDA_WS_XMIN; x <= NDS_PANDA_WS_XMAX + 1e-9; x += 0.0137) {
    for (double y = NDS_PANDA_WS_YMIN; y <= NDS_PANDA_WS_YMAX + 1e-9; y += 0.0213) {
      const double t[3] = {x, y, z}, p[2] = {x, y};
      if (nds_panda_ik(&cfg, t, NULL, q, err, sizeof err)) fail_msg("%s", err);
      assert_int_equal(nds_panda_rate_map(&cfg, q, m), 0);
      double lmin = INFINITY, lmax = 0.0;
      for (int k = 0; k < 12; k++) {
        const double u[2] = {cos(k * ND_PI / 12), sin(k * ND_PI / 12)};
        const double v[2] = {S * u[0], S * u[1]}, a[2] = {u[0], u[1]};
        double dv = 0.0, da = 0.0;
        for (int i = 0; i < NJ; i++) {
          const double rate = fabs(m[i][0] * u[0] + m[i][1] * u[1]);
          dv = fmax(dv, S * rate / nds_panda_dq_max[i]);
          da = fmax(da, rate / nds_panda_ddq_max[i]);
        }
        double qd[NJ], qdd[NJ], qd2[NJ], qdd2[NJ], mv = 0.0;
        assert_int_equal(nds_reach_joint(&r, p, v, zero, qd, qdd), 0);
        for (int i = 0; i < NJ; i++) mv = fmax(mv, fabs(qd[i]) / nds_panda_dq_max[i]);
        const double ma = nds_reach_load(&r, p, zero, a);
        worst_rel = fmax(worst_rel, fmax(fabs(mv / dv - 1.0), fabs(ma / da - 1.0)));
        lmin = fmin(lmin, mv);
        lmax = fmax(lmax, mv);
        /* Rates linear in the speed, their velocity-product accelerations quadratic; the
         * load the larger over all. */
        const double v2[2] = {2 * v[0], 2 * v[1]};
        assert_int_equal(nds_reach_joint(&r, p, v2, zero, qd2, qdd2), 0);
        for (int i = 0; i < NJ; i++) {
          assert_near(qd2[i], 2 * qd[i], 1e-9);
          assert_near(qdd2[i], 4 * qdd[i], 1e-9);
        }
        assert_true(nds_reach_load(&r, p, v, a) >= fmax(mv, ma) - 1e-12);
        /* IK's second difference along the path at speed S, 1 mm either side. */
        const double d = 1e-3, tp[3] = {x + d * u[0], y + d * u[1], z},
                     tm[3] = {x - d * u[0], y - d * u[1], z};
        double qp[NJ], qm[NJ];
        if (nds_panda_ik(&cfg, tp, q, qp, err, sizeof err) ||
            nds_panda_ik(&cfg, tm, q, qm, err, sizeof err))
          fail_msg("%s", err);
        for (int i = 0; i < NJ; i++) {
          const double ik = (qp[i] - 2 * q[i] + qm[i]) / (d * d) * S * S;
          const double e = fabs(qdd[i] - ik) / nds_panda_ddq_max[i];
          if (i == 1 || i == 3) vp_err = fmax(vp_err, e);
          else vp_err_self = fmax(vp_err_self, e);
          vp_max = fmax(vp_max, fabs(ik) / nds_panda_ddq_max[i]);
        }
      }
      /* No direction beyond the worst one nds_panda_speed_ratio gives. */
      assert_true(lmax <= nds_panda_speed_ratio(&cfg, q, S) * 1.05);
      lab_worst = fmax(lab_worst, lmax);
      spread = fmin(spread, lmin / lmax);
    }
  }
  int over = 0, unreachable = -1;
  for (int c = 0; c < r.nx * r.ny; c++) {
    const float *cell = r.rate + 2 * NJ * c;
    if (!isfinite(cell[0])) {
      unreachable = c;
      continue;
    }
    for (int i = 0, hit = 0; i < NJ && !hit; i++)
      over += hit = S * hypot(cell[2 * i], cell[2 * i + 1]) / nds_panda_dq_max[i] > 1.0;
  }
  print_message("reach: map vs IK within %.2f %%, lab box at 0.5 m/s worst %.3f, least over "
                "most loaded direction %.2f, %d of %d cells beyond 0.5 m/s, %d unreachable; "
                "velocity-product acceleration at 0.5 m/s up to %.3f of a limit, the map's "
                "off IK's by at most %.3f (joints 2 and 4), %.3f (the others)\n",
                100 * worst_rel, lab_worst, spread, over, r.nx * r.ny, r.unreachable, vp_max,
                vp_err, vp_err_self);
  assert_true(worst_rel < 0.05);
  assert_true(vp_max > 0.3);  /* worth counting at the lab's speed */
  /* The pitch joints set the sphere's reach and agree; the others also carry the arm's
   * self-motion, whose second derivative depends on how IK resolves the redundancy (the
   * map's neighbour-seeded branch, this check's seed). */
  assert_true(vp_err < 0.1);
  assert_true(vp_err_self < 0.3);
  assert_true(lab_worst <= NDS_PANDA_WS_SPEED_RATIO * 1.02);
  assert_true(spread < 0.5);
  assert_true(over > 0);
  const double off_map[2] = {0.8, 0.0}, slow[2] = {0.1, 0.0};
  assert_true(isinf(nds_reach_load(&r, off_map, slow, zero)));
  assert_true(isinf(nds_reach_load(&r, (const double[2]){NAN, 0.0}, slow, zero)));
  assert_int_equal(unreachable >= 0, r.unreachable > 0);
  if (unreachable >= 0) {
    const double p[2] = {lo[0] + (unreachable % r.nx) * 0.02, lo[1] + (unreachable / r.nx) * 0.02};
    assert_true(isinf(nds_reach_load(&r, p, zero, zero)));
  }
  nds_reach_free(&r);
  const double bad_hi[2] = {-0.4, 0.0};
  assert_int_equal(nds_reach_build(&r, &cfg, lo, bad_hi, 0.02, err, sizeof err), -1);
  assert_contains(err, "reach: box");
}

/* ---- control ---- */

/* Typical pushing keypoints (x, y, vx, vy) in the workspace; each min-snap segment starts
 * at 0.3 s and is stretched by 10% steps until it stays within 0.5 m/s and 2 m/s^2, as
 * the executor stretches its segments to its limits. */
static const double keys[][4] = {
    {0.00, 0.00, 0.3, 0.0},    {0.10, 0.02, 0.2, 0.1},     {0.10, 0.15, -0.1, 0.3},
    {0.00, 0.30, -0.3, 0.0},   {-0.12, 0.25, -0.1, -0.3},  {-0.12, 0.00, 0.0, -0.3},
    {-0.10, -0.25, 0.3, 0.0},  {0.10, -0.15, 0.0, 0.3},    {-0.10, 0.0, 0, 0}};
#define NKEYS ((int)(sizeof(keys) / sizeof(keys[0])))

typedef struct {
  double err_p50, err_p99, err_max; /* sphere centre to setpoint, m */
  double z_min;                     /* lowest sphere centre, m */
  int sat;                          /* OR of the controller's saturation masks */
  int reflexes;                     /* cycles the monitor flagged */
  nds_panda_reflex first;           /* the first one */
  int table_contacts, box_contacts; /* contacts of the sphere summed over steps */
  double q_end[NJ];
} run_stats;

static double errs[20000];

/* Track the keypoints (or the first nkeys of them) from the rest posture, a_limit the
 * segments' acceleration bound, then hold the last one for 0.5 s. */
static void run_keys(world *w, const nds_panda_gains *g, int nkeys, double a_limit,
                     int accel_window, run_stats *st) {
  char err[256] = "";
  nds_panda_ctrl c;
  if (nds_panda_ctrl_init(&c, w->m, g, err, sizeof(err))) fail_msg("%s", err);
  nds_panda_monitor mo;
  nds_panda_monitor_reset(&mo, DT, accel_window);
  memset(st, 0, sizeof(*st));
  st->z_min = INFINITY;
  const double z = nds_panda_push_height(&w->cfg);
  double s0[2][4] = {{-0.10, 0, 0, 0}, {0, 0, 0, 0}};
  int ne = 0;
  for (int k = 0; k < nkeys; k++) {
    nd_snap_seg seg;
    const double p1[2] = {keys[k][0], keys[k][1]}, v1[2] = {keys[k][2], keys[k][3]};
    double T = 0.3;
    for (;; T *= 1.1) {
      T = ceil(T / DT - 1e-9) * DT;
      nd_snap_seg_make(&seg, s0, p1, v1, T);
      double pv = 0, pa = 0, sp[2][4];
      for (int n = 0; n <= 200; n++) {
        nd_snap_seg_eval(&seg, T * n / 200, sp);
        pv = fmax(pv, hypot(sp[0][ND_V], sp[1][ND_V]));
        pa = fmax(pa, hypot(sp[0][ND_A], sp[1][ND_A]));
      }
      if (pv <= 0.5 && pa <= a_limit) break;
    }
    int steps = (int)lround(T / DT) + (k == nkeys - 1 ? 500 : 0);
    for (int n = 1; n <= steps; n++) {
      double sp[2][4], tau[NJ], q[NJ], dq[NJ];
      nd_snap_seg_eval(&seg, n * DT, sp);
      const double pd[3] = {sp[0][ND_P], sp[1][ND_P], z};
      const double vd[3] = {sp[0][ND_V], sp[1][ND_V], 0};
      const double ad[3] = {sp[0][ND_A], sp[1][ND_A], 0};
      mj_step1(w->m, w->d);
      const double *s = w->d->site_xpos + 3 * w->p.site_tool;
      double e = dist3(s, pd);
      assert_true(ne < (int)(sizeof(errs) / sizeof(errs[0])));
      errs[ne++] = e;
      st->err_max = fmax(st->err_max, e);
      st->z_min = fmin(st->z_min, s[2]);
      st->sat |= nds_panda_ctrl_impedance(&c, &w->p, w->m, w->d, pd, vd, ad, tau);
      nds_panda_get_q(&w->p, w->d, q, dq);
      nds_panda_reflex r;
      if (nds_panda_monitor_check(&mo, q, dq, pd, &r) && st->reflexes++ == 0) st->first = r;
      nds_panda_apply(&w->p, w->d, tau);
      mj_step2(w->m, w->d);
      for (int i = 0; i < w->d->ncon; i++) {
        int g1 = w->d->contact[i].geom1, g2 = w->d->contact[i].geom2;
        if (g1 != w->p.geom_sphere && g2 != w->p.geom_sphere) continue;
        int other = g1 == w->p.geom_sphere ? g2 : g1;
        if (w->m->geom_bodyid[other] == 0)
          st->table_contacts++;
        else
          st->box_contacts++;
      }
    }
    nd_snap_seg_eval(&seg, T, s0);
  }
  qsort(errs, ne, sizeof(double), cmp_double);
  st->err_p50 = errs[ne / 2];
  st->err_p99 = errs[(int)(0.99 * ne)];
  nds_panda_get_q(&w->p, w->d, st->q_end, NULL);
  nds_panda_ctrl_free(&c);
}

/* Free space: the sphere follows the segments within a millimetre and a half, no joint
 * needs its torque clamped and no reflex (joint accelerations over single cycles
 * included) trips; the null-space pull brings the elbow and wrist back to rest, where
 * without it they wander off. */
static void test_tracking_and_nullspace(void **state) {
  (void)state;
  world w;
  world_open(&w, 0);
  nds_panda_gains g;
  nds_panda_gains_default(&g);
  run_stats st;
  run_keys(&w, &g, NKEYS, 2.0, 1, &st);
  print_message("free space: error p50 %.2f mm, p99 %.2f mm, max %.2f mm\n",
                1e3 * st.err_p50, 1e3 * st.err_p99, 1e3 * st.err_max);
  assert_true(st.err_p99 < 1.5e-3);
  assert_true(st.err_max < 2e-3);
  assert_int_equal(st.sat, 0);
  assert_int_equal(st.reflexes, 0);
  assert_true(st.z_min > w.cfg.ee_radius);
  for (int i = 0; i < NJ; i++) assert_near(st.q_end[i], w.cfg.q_rest[i], 0.02);

  /* Elbow drift without the null-space pull: the same run ends with joint 1 turned
   * well away from rest (the self-motion is unconstrained). */
  world_close(&w);
  world_open(&w, 0);
  g.k_ns = g.d_ns = 0;
  run_keys(&w, &g, NKEYS, 2.0, 1, &st);
  double drift = 0;
  for (int i = 0; i < NJ; i++) drift = fmax(drift, fabs(st.q_end[i] - w.cfg.q_rest[i]));
  print_message("without null space: largest joint drift %.3f rad\n", drift);
  assert_true(drift > 0.1);
  world_close(&w);
}

/* Pushing the 0.5 kg box: the sphere strikes and pushes it forward, yields a few
 * millimetres to it (more than in free space, never a centimetre), never touches the
 * table, never needs a clamped torque, and trips no reflex with the pushing window for
 * joint accelerations, where single cycles would (the impact). */
static void test_push_box(void **state) {
  (void)state;
  world w;
  world_open(&w, 1);
  nds_panda_gains g;
  nds_panda_gains_default(&g);
  run_stats st;
  run_keys(&w, &g, NKEYS, 2.0, NDS_PANDA_ACCEL_WINDOW_PUSH, &st);
  print_message("push: error p50 %.2f mm, p99 %.2f mm, max %.2f mm; box at (%.3f, %.3f)\n",
                1e3 * st.err_p50, 1e3 * st.err_p99, 1e3 * st.err_max, w.d->qpos[0],
                w.d->qpos[1]);
  assert_true(st.box_contacts > 100);
  assert_int_equal(st.table_contacts, 0);
  assert_true(w.d->qpos[0] > 0.1); /* the box went forward */
  assert_true(st.err_max > 2e-3);  /* compliant: it gives way to the box */
  assert_true(st.err_p99 < 5e-3);
  assert_true(st.z_min > w.cfg.ee_radius);
  assert_int_equal(st.sat, 0);
  assert_int_equal(st.reflexes, 0);
  world_close(&w);

  world_open(&w, 1);
  run_keys(&w, &g, NKEYS, 2.0, 1, &st);
  assert_true(st.reflexes > 0);
  assert_int_equal(st.first.kind, NDS_PANDA_REFLEX_JOINT_ACCELERATION);
  world_close(&w);
}

/* A fast sweep across the workspace within the Cartesian limits (1.2 m/s, ~5 m/s^2):
 * the arm tracks it until a joint passes libfranka's velocity limit, which the reflex
 * check names. With single-cycle joint accelerations checked, an acceleration limit
 * breaks first. */
static void test_reflex_on_fast_segment(void **state) {
  (void)state;
  for (int window = 0; window <= 1; window++) {
    world w;
    world_open(&w, 0);
    char err[256] = "", name[64];
    nds_panda_gains g;
    nds_panda_gains_default(&g);
    nds_panda_ctrl c;
    if (nds_panda_ctrl_init(&c, w.m, &g, err, sizeof(err))) fail_msg("%s", err);
    nds_panda_monitor mo;
    nds_panda_monitor_reset(&mo, DT, window);
    const double z = nds_panda_push_height(&w.cfg);
    double q[NJ], start[3] = {-0.10, -0.20, z};
    if (nds_panda_ik(&w.cfg, start, NULL, q, err, sizeof(err))) fail_msg("%s", err);
    nds_panda_set_q(&w.p, w.m, w.d, q);
    double s0[2][4] = {{-0.10, 0, 0, 0}, {-0.20, 0, 0, 0}};
    const double p1[2] = {-0.10, 0.30}, v1[2] = {0, 0};
    nd_snap_seg seg;
    nd_snap_seg_make(&seg, s0, p1, v1, 0.9);
    nds_panda_reflex r = {NDS_PANDA_REFLEX_NONE, -1, 0, 0};
    int n;
    for (n = 1; n <= 900; n++) {
      double sp[2][4], tau[NJ], dq[NJ];
      nd_snap_seg_eval(&seg, n * DT, sp);
      const double pd[3] = {sp[0][ND_P], sp[1][ND_P], z};
      const double vd[3] = {sp[0][ND_V], sp[1][ND_V], 0};
      const double ad[3] = {sp[0][ND_A], sp[1][ND_A], 0};
      mj_step1(w.m, w.d);
      nds_panda_ctrl_impedance(&c, &w.p, w.m, w.d, pd, vd, ad, tau);
      nds_panda_get_q(&w.p, w.d, q, dq);
      if (nds_panda_monitor_check(&mo, q, dq, pd, &r)) break;
      nds_panda_apply(&w.p, w.d, tau);
      mj_step2(w.m, w.d);
    }
    print_message("window %d: reflex \"%s\" at %d ms: %.3f (limit %.3f)\n", window,
                  nds_panda_reflex_name(&r, name, sizeof(name)), n, r.value, r.limit);
    assert_true(n <= 900);
    assert_int_equal(r.kind, window ? NDS_PANDA_REFLEX_JOINT_ACCELERATION
                                    : NDS_PANDA_REFLEX_JOINT_VELOCITY);
    assert_in_range(r.joint, 0, NJ - 1);
    assert_true(fabs(r.value) > fabs(r.limit));
    if (!window) {
      /* The broken limit is libfranka's kMaxJointVelocity for that joint. */
      double lim =
          nds_panda_dq_max[r.joint] - 1e-3 - 3e-3 * (nds_panda_ddq_max[r.joint] - 1e-3);
      assert_near(fabs(r.limit), lim, 1e-12);
      char want[32];
      snprintf(want, sizeof(want), "joint %d velocity", r.joint + 1);
      assert_string_equal(name, want);
    }
    nds_panda_ctrl_free(&c);
    world_close(&w);
  }
}

/* The brake law stops an arm moving at ~0.4 m/s and then holds it: over the second after
 * it has settled (0.5 s) the sphere moves less than a millimetre. */
static void test_brake_holds(void **state) {
  (void)state;
  world w;
  world_open(&w, 0);
  char err[256] = "";
  nds_panda_gains g;
  nds_panda_gains_default(&g);
  nds_panda_ctrl c;
  if (nds_panda_ctrl_init(&c, w.m, &g, err, sizeof(err))) fail_msg("%s", err);
  const double z = nds_panda_push_height(&w.cfg);
  double s0[2][4] = {{-0.10, 0, 0, 0}, {0, 0, 0, 0}};
  const double p1[2] = {0.10, 0.10}, v1[2] = {0, 0};
  nd_snap_seg seg;
  nd_snap_seg_make(&seg, s0, p1, v1, 1.2);
  double tau[NJ], q_hold[NJ], dq[NJ], speed = 0;
  for (int n = 1; n <= 600; n++) { /* half-way: at top speed */
    double sp[2][4];
    nd_snap_seg_eval(&seg, n * DT, sp);
    const double pd[3] = {sp[0][ND_P], sp[1][ND_P], z};
    const double vd[3] = {sp[0][ND_V], sp[1][ND_V], 0};
    const double ad[3] = {sp[0][ND_A], sp[1][ND_A], 0};
    mj_step1(w.m, w.d);
    nds_panda_ctrl_impedance(&c, &w.p, w.m, w.d, pd, vd, ad, tau);
    nds_panda_apply(&w.p, w.d, tau);
    mj_step2(w.m, w.d);
    speed = hypot(sp[0][ND_V], sp[1][ND_V]);
  }
  assert_true(speed > 0.3);
  nds_panda_get_q(&w.p, w.d, q_hold, NULL);
  double p_settled[3] = {0}, p_end[3];
  for (int n = 1; n <= 1500; n++) {
    mj_step1(w.m, w.d);
    int sat = nds_panda_ctrl_brake(&w.p, w.d, q_hold, tau);
    (void)sat;
    nds_panda_apply(&w.p, w.d, tau);
    mj_step2(w.m, w.d);
    if (n == 500) memcpy(p_settled, w.d->site_xpos + 3 * w.p.site_tool, sizeof(p_settled));
  }
  mj_forward(w.m, w.d);
  memcpy(p_end, w.d->site_xpos + 3 * w.p.site_tool, sizeof(p_end));
  nds_panda_get_q(&w.p, w.d, NULL, dq);
  print_message("brake: drift over 1 s after settling %.4f mm\n",
                1e3 * dist3(p_end, p_settled));
  assert_true(dist3(p_end, p_settled) < 1e-3);
  for (int i = 0; i < NJ; i++) assert_near(dq[i], 0, 1e-3);
  nds_panda_ctrl_free(&c);
  world_close(&w);
}

/* ---- reflexes on synthetic inputs ---- */

static int check(nds_panda_monitor *mo, const double q[NJ], const double dq[NJ],
                 const double p[3], nds_panda_reflex *r) {
  return nds_panda_monitor_check(mo, q, dq, p, r);
}

static void test_reflex_kinds(void **state) {
  (void)state;
  nds_panda_cfg cfg;
  nds_panda_cfg_default(&cfg);
  nds_panda_monitor mo;
  nds_panda_reflex r;
  char name[64];
  double q[NJ], dq[NJ] = {0}, p[3] = {0, 0, 0.026};
  memcpy(q, cfg.q_rest, sizeof(q));

  /* Joint position: within kLimitEps of joint 4's upper limit. */
  nds_panda_monitor_reset(&mo, DT, 1);
  q[3] = nds_panda_q_max[3] - 0.5e-3;
  assert_int_equal(check(&mo, q, dq, p, &r), 1);
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_JOINT_POSITION);
  assert_int_equal(r.joint, 3);
  assert_near(r.limit, nds_panda_q_max[3] - 1e-3, 1e-15);
  assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)), "joint 4 position");
  q[3] = cfg.q_rest[3];

  /* Joint velocity: 2.15 rad/s on joint 4 is past kMaxJointVelocity (2.1365). */
  nds_panda_monitor_reset(&mo, DT, 0);
  dq[3] = -2.15;
  assert_int_equal(check(&mo, q, dq, p, &r), 1);
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_JOINT_VELOCITY);
  assert_near(r.value, -2.15, 0);
  assert_near(r.limit, -(2.175 - 1e-3 - 3e-3 * (12.5 - 1e-3)), 1e-12);
  assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)), "joint 4 velocity");
  dq[3] = 2.12;
  assert_int_equal(check(&mo, q, dq, p, &r), 0);
  dq[3] = 0;

  /* Joint acceleration: joint 2 gains 0.02 rad/s in one cycle (20 rad/s^2 > 7.5); over
   * a 10-cycle window the same change reads 2 rad/s^2. */
  nds_panda_monitor_reset(&mo, DT, 1);
  assert_int_equal(check(&mo, q, dq, p, &r), 0);
  dq[1] = 0.02;
  assert_int_equal(check(&mo, q, dq, p, &r), 1);
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_JOINT_ACCELERATION);
  assert_int_equal(r.joint, 1);
  assert_near(r.value, 20, 1e-9);
  assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)),
                      "joint 2 acceleration");
  nds_panda_monitor_reset(&mo, DT, 10);
  dq[1] = 0;
  for (int k = 0; k < 10; k++) assert_int_equal(check(&mo, q, dq, p, &r), 0);
  dq[1] = 0.02;
  for (int k = 0; k < 10; k++) assert_int_equal(check(&mo, q, dq, p, &r), 0);
  dq[1] = 0;

  /* Cartesian velocity: a 1 cm setpoint step is 10 m/s; 1.65 m/s passes, 1.67 does not
   * (kMaxTranslationalVelocity 1.66). */
  nds_panda_monitor_reset(&mo, DT, 0);
  assert_int_equal(check(&mo, q, dq, p, &r), 0);
  p[0] += 0.01;
  assert_int_equal(check(&mo, q, dq, p, &r), 1);
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_CART_VELOCITY);
  assert_int_equal(r.joint, -1);
  assert_near(r.value, 10, 1e-9);
  assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)), "Cartesian velocity");
  for (int pass = 0; pass < 2; pass++) {
    double v = pass ? 1.67 : 1.65;
    nds_panda_monitor_reset(&mo, DT, 0);
    int broke = 0;
    for (int k = 0; k < 10; k++) {
      double pk[3] = {v * k * DT, 0, 0.026};
      broke |= check(&mo, q, dq, pk, &r);
    }
    assert_int_equal(broke, pass);
  }

  /* Cartesian acceleration: from rest at 13.5 m/s^2 breaks on the third sample, where the
   * second difference first exists. */
  nds_panda_monitor_reset(&mo, DT, 0);
  for (int k = 0; k < 3; k++) {
    double pk[3] = {0.5 * 13.5 * (k * DT) * (k * DT), 0, 0.026};
    int rc = check(&mo, q, dq, pk, &r);
    assert_int_equal(rc, k == 2);
  }
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_CART_ACCELERATION);
  assert_near(r.value, 13.5, 1e-6);
  assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)),
                      "Cartesian acceleration");

  /* Cartesian jerk: positions J dt^3 C(k, 3) have third difference J and second J dt
   * (6.6 m/s^2): J = 6600 breaks the 6500 m/s^3 limit alone, 6400 passes. */
  for (int pass = 0; pass < 2; pass++) {
    double J = pass ? 6600 : 6400;
    nds_panda_monitor_reset(&mo, DT, 0);
    int broke = 0;
    for (int k = 0; k < 4; k++) {
      double pk[3] = {J * DT * DT * DT * k * (k - 1) * (k - 2) / 6, 0, 0.026};
      broke |= check(&mo, q, dq, pk, &r);
    }
    assert_int_equal(broke, pass);
    if (pass) {
      assert_int_equal(r.kind, NDS_PANDA_REFLEX_CART_JERK);
      assert_near(r.value, 6600, 1e-3);
      assert_string_equal(nds_panda_reflex_name(&r, name, sizeof(name)), "Cartesian jerk");
    }
  }

  /* Not finite. */
  nds_panda_monitor_reset(&mo, DT, 1);
  p[1] = NAN;
  assert_int_equal(check(&mo, q, dq, p, &r), 1);
  assert_int_equal(r.kind, NDS_PANDA_REFLEX_NONFINITE);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_model_structure),
      cmocka_unit_test(test_xml_pieces),
      cmocka_unit_test(test_ctrl_model_mismatch),
      cmocka_unit_test(test_cfg_check),
      cmocka_unit_test(test_fk_matches_mujoco),
      cmocka_unit_test(test_ik_workspace_grid),
      cmocka_unit_test(test_tracking_and_nullspace),
      cmocka_unit_test(test_push_box),
      cmocka_unit_test(test_reflex_on_fast_segment),
      cmocka_unit_test(test_brake_holds),
      cmocka_unit_test(test_reflex_kinds),
      cmocka_unit_test(test_reach_map),
      cmocka_unit_test(test_reach_lab_caps),
      cmocka_unit_test(test_stale_brake_lab),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
