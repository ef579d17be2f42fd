/* test_model: the scene, theta, model files, state sync and the tracking controller. */
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_test.h"
#include "nds_test.h"
#include "nds_ctrl.h"
#include "nds_model.h"
#include "nds_state.h"

static void build(nds_model *nm, const nds_scene_cfg *cfg) {
  char err[256] = "";
  if (nds_model_init(nm, cfg, err, sizeof(err))) fail_msg("nds_model_init: %s", err);
}

static void build_default(nds_model *nm) {
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  build(nm, &cfg);
}

#define assert_contains(s, sub)                                                    \
  do {                                                                             \
    if (!strstr((s), (sub))) fail_msg("\"%s\" does not mention \"%s\"", (s), (sub)); \
  } while (0)

static void test_default_scene(void **state) {
  (void)state;
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  nds_model nm;
  build(&nm, &cfg);
  const mjModel *m = nm.m;
  assert_int_equal(m->nq, 9);
  assert_int_equal(m->nv, 8);
  assert_int_equal(nm.obj_qpos, 0);
  assert_int_equal(nm.obj_dof, 0);
  assert_int_equal(nm.ee_qpos[0], 7);
  assert_int_equal(nm.ee_dof[1], 7);
  assert_near(m->opt.timestep, 0.001, 0);
  assert_int_equal(m->opt.cone, mjCONE_ELLIPTIC);
  assert_near(m->opt.noslip_iterations, 0, 0);
  /* The sphere hangs just above the table with its centre below the box top. */
  assert_true(nm.ee_height > cfg.ee_radius);
  assert_true(nm.ee_height < cfg.ee_radius + 0.002);
  assert_true(nm.ee_height < 2 * cfg.obj_half[2]);
  for (int g = 0; g < m->ngeom; g++) {
    assert_int_equal(m->geom_condim[g], 6);
    for (int k = 0; k < 3; k++) assert_near(m->geom_friction[3 * g + k], nd_theta_true[k], 0);
  }
  assert_near(m->body_mass[nm.obj_body], 0.5, 1e-15);
  assert_near(m->body_mass[nm.ee_body], nd_theta_true[ND_TH_MASS], 0);
  /* Box inertia of a uniform 10 x 6 x 5 cm, 0.5 kg cuboid about z: m/12 (a^2 + b^2). */
  assert_near(m->body_inertia[3 * nm.obj_body + 2], 0.5 / 12 * (0.01 + 0.0036), 1e-15);
  /* Only roll and pitch of the object are damped. */
  assert_near(m->dof_damping[3], cfg.tilt_damping, 0);
  assert_near(m->dof_damping[4], cfg.tilt_damping, 0);
  assert_near(m->dof_damping[5], 0, 0);
  assert_near(m->dof_damping[0] + m->dof_damping[6] + m->dof_damping[7], 0, 0);
  /* The sphere-table pair is excluded. */
  assert_int_equal(m->nexclude, 1);
  nds_model_free(&nm);
  nds_model_free(&nm); /* idempotent */
}

static void expect_cfg_error(const nds_scene_cfg *cfg, const char *what) {
  char err[256] = "";
  nds_model nm;
  assert_int_equal(nds_model_init(&nm, cfg, err, sizeof(err)), -1);
  assert_null(nm.m);
  assert_contains(err, what);
  assert_int_equal(nds_scene_cfg_check(cfg, err, sizeof(err)), -1);
}

static void test_bad_cfg_rejected(void **state) {
  (void)state;
  nds_scene_cfg c0, c;
  nds_scene_cfg_default(&c0);
  c = c0, c.obj_half[1] = -0.01, expect_cfg_error(&c, "obj_half[1] = -0.01");
  c = c0, c.obj_half[2] = 0, expect_cfg_error(&c, "obj_half[2]");
  c = c0, c.obj_mass = 0, expect_cfg_error(&c, "obj_mass = 0");
  c = c0, c.ee_radius = NAN, expect_cfg_error(&c, "ee_radius = nan");
  c = c0, c.ee_radius = 0.05, expect_cfg_error(&c, "below the object top");
  c = c0, c.timestep = 0.06, expect_cfg_error(&c, "timestep = 0.06");
  c = c0, c.timestep = 0, expect_cfg_error(&c, "timestep = 0");
  c = c0, c.timestep = -1e-3, expect_cfg_error(&c, "timestep");
  c = c0, c.condim = 5, expect_cfg_error(&c, "condim = 5");
  c = c0, c.condim = 1, expect_cfg_error(&c, "condim = 1");
  c = c0, c.tilt_damping = -1, expect_cfg_error(&c, "tilt_damping = -1");
  c = c0, c.theta[ND_TH_MASS] = 0, expect_cfg_error(&c, "sphere mass");
  c = c0, c.timestep = 0.05, c.condim = 3;
  char err[256] = "";
  assert_int_equal(nds_scene_cfg_check(&c, err, sizeof(err)), 0);

  char small[64];
  assert_int_equal(nds_scene_xml(&c0, small, sizeof(small), err, sizeof(err)), -1);
  assert_contains(err, "buffer has 64");
}

static void test_bad_theta_rejected(void **state) {
  (void)state;
  nds_model nm;
  build_default(&nm);
  struct {
    double theta[ND_NTHETA];
    const char *what;
  } bad[] = {
      {{NAN, 0.005, 1e-4, 1}, "theta[0] (sliding friction) = nan"},
      {{-0.1, 0.005, 1e-4, 1}, "sliding friction"},
      {{1, -1e-3, 1e-4, 1}, "torsional friction"},
      {{1, 0.005, INFINITY, 1}, "rolling friction"},
      {{1, 0.005, 1e-4, 0}, "theta[3] (sphere mass) = 0"},
      {{1, 0.005, 1e-4, -2}, "sphere mass"},
  };
  double fr[9], mass = nm.m->body_mass[nm.ee_body];
  memcpy(fr, nm.m->geom_friction, sizeof(fr));
  for (size_t i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
    char err[256] = "";
    assert_int_equal(nd_theta_check(bad[i].theta, err, sizeof(err)), -1);
    assert_contains(err, bad[i].what);
    err[0] = 0;
    assert_int_equal(nds_theta_apply(&nm, bad[i].theta, err, sizeof(err)), -1);
    assert_contains(err, bad[i].what);
  }
  assert_memory_equal(fr, nm.m->geom_friction, sizeof(fr));
  assert_near(nm.m->body_mass[nm.ee_body], mass, 0);
  /* Zero friction is a valid (if slippery) world. */
  double ok[ND_NTHETA] = {0, 0, 0, 0.2, 1, 0, 0};
  char err[256];
  assert_int_equal(nd_theta_check(ok, err, sizeof(err)), 0);
  nds_model_free(&nm);
}

/* Command-line theta: every refusal names the option, whatever part of the check fails. */
static void test_theta_parse(void **state) {
  (void)state;
  double th[ND_NTHETA];
  char err[256];
  assert_int_equal(nd_theta_parse("0.3,0.005,1e-4,1.5", "--theta", th, err, sizeof(err)), 0);
  assert_near(th[ND_TH_SLIDE], 0.3, 0);
  assert_near(th[ND_TH_MASS], 1.5, 0);
  /* Zero friction is a valid world, as in nd_theta_check. */
  assert_int_equal(nd_theta_parse("0,0,0,1", "--theta", th, err, sizeof(err)), 0);
  struct {
    const char *s, *what;
  } bad[] = {
      {"-0.1,0.005,1e-4,1", "theta[0] (sliding friction) = -0.1"},  /* negative */
      {"1,0.005,1e-4,1,1,0.06,0", "theta[5] (box COM shift x) = 0.06"},  /* outside */
      {"1,0.005,1e-4,1,-1,0,0", "theta[4] (box mass scale) = -1"},
      {"1,0.005,1e-4,0", "theta[3] (sphere mass) = 0"},        /* zero mass */
      {"1,0.005,1e-4,-0", "theta[3] (sphere mass) = -0"},      /* signed zero */
      {"nan,0.005,1e-4,1", "'nan' is not a finite number"},    /* NaN */
      {"1,inf,1e-4,1", "'inf' is not a finite number"},        /* infinite */
      {"1,0.005,1e-4,1e5", "100000 is out of range"},          /* absurd */
      {"1,0.005,1e-4", "expected 4 values"},  /* too few */
      {"1,0.005,1e-4,1,1", "expected 4 values"},  /* too many */
      {"1;0.005;1e-4;1", "expected 4 values"},
      {"", "expected 4 values"},
  };
  for (size_t i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
    err[0] = 0;
    if (nd_theta_parse(bad[i].s, "--prior-ref", th, err, sizeof(err)) != -1)
      fail_msg("'%s' accepted", bad[i].s);
    assert_contains(err, "--prior-ref");
    assert_contains(err, bad[i].what);
  }
}

/* ma's masses and inertias (within inertia_tol) and what MuJoCo derives from them equal
 * mb's: subtree masses, inverse weights, the mass matrix's diagonal at qpos0. */
static void expect_mass_derived(const mjModel *ma, const mjModel *mb, double inertia_tol) {
  for (int i = 0; i < ma->nbody; i++) {
    assert_near(ma->body_mass[i], mb->body_mass[i], 1e-15);
    assert_near(ma->body_subtreemass[i], mb->body_subtreemass[i], 1e-15);
    for (int k = 0; k < 3; k++)
      assert_near(ma->body_inertia[3 * i + k], mb->body_inertia[3 * i + k], inertia_tol);
    for (int k = 0; k < 2; k++)
      assert_near(ma->body_invweight0[2 * i + k], mb->body_invweight0[2 * i + k],
                  1e-12 * fabs(mb->body_invweight0[2 * i + k]));
  }
  for (int i = 0; i < ma->nv; i++) {
    assert_near(ma->dof_invweight0[i], mb->dof_invweight0[i], 1e-12 * mb->dof_invweight0[i]);
    assert_near(ma->dof_M0[i], mb->dof_M0[i], 1e-12 * mb->dof_M0[i]);
  }
}

/* Applying theta to a built model gives the model built with that theta: friction,
 * mass, inertia and every quantity MuJoCo derives from mass at compile time. */
static void test_theta_apply_matches_build(void **state) {
  (void)state;
  const double th[ND_NTHETA] = {0.7, 0.01, 0.001, 0.3, 1, 0, 0};
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  nds_model a, b;
  build(&a, &cfg);
  memcpy(cfg.theta, th, sizeof(th));
  build(&b, &cfg);
  char err[256];
  assert_int_equal(nds_theta_apply(&a, th, err, sizeof(err)), 0);
  const mjModel *ma = a.m, *mb = b.m;
  for (int i = 0; i < 3 * ma->ngeom; i++) assert_near(ma->geom_friction[i], mb->geom_friction[i], 0);
  expect_mass_derived(ma, mb, 1e-18);
  assert_memory_equal(a.cfg.theta, th, sizeof(th));
  nds_model_free(&a);
  nds_model_free(&b);
}

/* The box's entries of theta give the model built with that box: 10 % heavier with its
 * centre of mass 8 mm forward and 4 mm to the right (the lab's box) equals a 0.55 kg box
 * built so, down to what MuJoCo derives from it. A shift out of the box is refused. */
static void test_theta_box_matches_build(void **state) {
  (void)state;
  const double th[ND_NTHETA] = {0.7, 0.01, 0.001, 0.3, 1.1, 0.008, -0.004};
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  nds_model a, b;
  build(&a, &cfg);
  memcpy(cfg.theta, th, sizeof(th));
  cfg.theta[ND_TH_BOX_SCALE] = 1, cfg.theta[ND_TH_COM_X] = 0, cfg.theta[ND_TH_COM_Y] = 0;
  cfg.obj_mass = 0.55, cfg.obj_com[0] = 0.008, cfg.obj_com[1] = -0.004;
  build(&b, &cfg);
  char err[256];
  assert_int_equal(nds_theta_apply(&a, th, err, sizeof(err)), 0);
  const mjModel *ma = a.m, *mb = b.m;
  const int o = a.obj_body;
  assert_near(ma->body_mass[o], 0.55, 1e-15);
  for (int k = 0; k < 3; k++) assert_near(ma->body_ipos[3 * o + k], mb->body_ipos[3 * o + k], 0);
  expect_mass_derived(ma, mb, 1e-15);
  /* The default box is 6 cm deep: a 3.1 cm shift across it leaves it. */
  double out[ND_NTHETA];
  memcpy(out, th, sizeof(out));
  out[ND_TH_COM_Y] = -0.031;
  assert_int_equal(nds_theta_apply(&a, out, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "theta[6] (box COM shift y) = -0.031 puts the centre of mass"));
  assert_near(ma->body_ipos[3 * o + 1], -0.004, 0);  /* refused: the model kept theta */
  out[ND_TH_SLIDE] = 0.2;
  assert_int_equal(nds_theta_apply(&a, out, err, sizeof(err)), -1);
  assert_near(ma->geom_friction[0], 0.7, 0);  /* its frictions too */
  assert_memory_equal(a.cfg.theta, th, sizeof(th));
  nds_model_free(&a);
  nds_model_free(&b);
}

/* theta fixes the model's bits: applying other values first and then theta gives exactly
 * what applying theta once gives (parameter fits rely on it: a worker's model holds
 * whatever the previous candidate left). */
static void test_theta_apply_idempotent(void **state) {
  (void)state;
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  nds_model a, b;
  build(&a, &cfg);
  build(&b, &cfg);
  char err[256];
  const double th[ND_NTHETA] = {0.9, 0.004, 0.0002, 1.37, 1.07, 0.003, -0.002};
  assert_int_equal(nds_theta_apply(&a, th, err, sizeof(err)), 0);
  for (int i = 0; i < 100; i++) {
    const double other[ND_NTHETA] = {0.3 + 0.01 * i, 0.001 * i,        1e-5 * i,
                                     0.2 + 0.037 * i, 0.5 + 0.01 * i, 1e-4 * i - 0.005,
                                     0.01 - 2e-4 * i};
    assert_int_equal(nds_theta_apply(&b, other, err, sizeof(err)), 0);
    assert_int_equal(nds_theta_apply(&b, th, err, sizeof(err)), 0);
  }
  const mjModel *ma = a.m, *mb = b.m;
  assert_memory_equal(ma->body_mass, mb->body_mass, sizeof(mjtNum) * ma->nbody);
  assert_memory_equal(ma->body_inertia, mb->body_inertia, sizeof(mjtNum) * 3 * ma->nbody);
  assert_memory_equal(ma->body_subtreemass, mb->body_subtreemass, sizeof(mjtNum) * ma->nbody);
  assert_memory_equal(ma->body_invweight0, mb->body_invweight0, sizeof(mjtNum) * 2 * ma->nbody);
  assert_memory_equal(ma->dof_invweight0, mb->dof_invweight0, sizeof(mjtNum) * ma->nv);
  assert_memory_equal(ma->dof_M0, mb->dof_M0, sizeof(mjtNum) * ma->nv);
  assert_memory_equal(ma->body_ipos, mb->body_ipos, sizeof(mjtNum) * 3 * ma->nbody);
  assert_memory_equal(ma->geom_friction, mb->geom_friction, sizeof(mjtNum) * 3 * ma->ngeom);
  nds_model_free(&a);
  nds_model_free(&b);
}

static void test_copy_is_independent(void **state) {
  (void)state;
  nds_model a, b;
  build_default(&a);
  char err[256];
  assert_int_equal(nds_model_copy(&b, &a, err, sizeof(err)), 0);
  assert_ptr_not_equal(a.m, b.m);
  double th[ND_NTHETA] = {0.3, 0.001, 0.0, 2.0, 1, 0, 0};
  assert_int_equal(nds_theta_apply(&b, th, err, sizeof(err)), 0);
  assert_near(a.m->geom_friction[0], 1.0, 0);
  assert_near(a.m->body_mass[a.ee_body], 1.0, 0);
  assert_near(b.m->body_mass[b.ee_body], 2.0, 0);
  nds_model_free(&a);
  nds_model_free(&b);
}

/* Under a constant force the sphere follows semi-implicit Euler exactly:
 * x_n = x_0 + F/m dt^2 n (n + 1) / 2. Four times the mass, a quarter of the travel. */
static void test_mass_changes_response(void **state) {
  (void)state;
  nds_model nm;
  build_default(&nm);
  mjData *d = mj_makeData(nm.m);
  const double F = 2.0, dt = nm.m->opt.timestep;
  const int n = 200;
  double travel[2];
  const double masses[2] = {0.5, 2.0};
  for (int j = 0; j < 2; j++) {
    double th[ND_NTHETA] = {1, 0.005, 1e-4, masses[j], 1, 0, 0};
    char err[256];
    assert_int_equal(nds_theta_apply(&nm, th, err, sizeof(err)), 0);
    nds_state s;
    const double ee[2] = {-0.3, 0.2};
    nds_state_rest(&nm, 0, 0, 0, ee, &s);
    assert_int_equal(nds_state_set(&nm, d, &s, err, sizeof(err)), 0);
    for (int i = 0; i < n; i++) {
      d->qfrc_applied[nm.ee_dof[0]] = F;
      mj_step(nm.m, d);
    }
    nds_state_get(&nm, d, &s);
    travel[j] = s.ee_pos[0] - ee[0];
    assert_near(travel[j], F / masses[j] * dt * dt * n * (n + 1) / 2, 1e-12);
    assert_near(s.ee_pos[1], ee[1], 1e-15);
  }
  printf("sphere_travel_0.5kg %.6f m\nsphere_travel_2kg %.6f m\n", travel[0], travel[1]);
  assert_near(travel[0] / travel[1], 4.0, 1e-9);
  mj_deleteData(d);
  nds_model_free(&nm);
}

/* A box left at rest stays put at every timestep the planner may use, and with the
 * sphere away from it only the box-table contacts exist. */
static void test_rest_is_stable(void **state) {
  (void)state;
  const double dts[4] = {0.001, 0.002, 0.005, 0.01};
  for (int i = 0; i < 4; i++) {
    nds_scene_cfg cfg;
    nds_scene_cfg_default(&cfg);
    cfg.timestep = dts[i];
    nds_model nm;
    build(&nm, &cfg);
    mjData *d = mj_makeData(nm.m);
    nds_state s, e;
    const double ee[2] = {-0.3, 0.0};
    nds_state_rest(&nm, 0.1, -0.05, 0.4, ee, &s);
    char err[256];
    assert_int_equal(nds_state_set(&nm, d, &s, err, sizeof(err)), 0);
    int n = (int)lround(1.0 / dts[i]);
    for (int k = 0; k < n; k++) mj_step(nm.m, d);
    nds_state_get(&nm, d, &e);
    assert_near(e.obj_pos[0], 0.1, 1e-4);
    assert_near(e.obj_pos[1], -0.05, 1e-4);
    assert_near(e.obj_pos[2], cfg.obj_half[2], 5e-4);
    assert_near(nds_state_yaw(&e), 0.4, 1e-4);
    assert_near(e.ee_pos[0], ee[0], 1e-12);
    assert_int_equal(d->ncon, 4);
    int nt = -1, ne = -1;
    nds_contacts(&nm, d, &nt, &ne);
    assert_int_equal(nt, 4);
    assert_int_equal(ne, 0);
    for (int w = 0; w < mjNWARNING; w++) assert_int_equal(d->warning[w].number, 0);
    mj_deleteData(d);
    nds_model_free(&nm);
  }
}

/* nds_contacts tells the sphere's contact from the table's: a sphere 0.5 mm into the box's
 * -x face adds one object-sphere contact to the four corners; one 1 mm clear adds none. */
static void test_contacts_by_pair(void **state) {
  (void)state;
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  nds_model nm;
  build(&nm, &cfg);
  mjData *d = mj_makeData(nm.m);
  const double depth[2] = {0.0005, -0.001};
  for (int i = 0; i < 2; i++) {
    nds_state s;
    const double ee[2] = {-cfg.obj_half[0] - cfg.ee_radius + depth[i], 0.0};
    nds_state_rest(&nm, 0.0, 0.0, 0.0, ee, &s);
    char err[256];
    assert_int_equal(nds_state_set(&nm, d, &s, err, sizeof(err)), 0);
    for (int k = 0; k < 300; k++) mj_step(nm.m, d);
    /* Settled on the table, then the sphere put back where the case wants it. */
    nds_state_get(&nm, d, &s);
    s.ee_pos[0] = ee[0] + s.obj_pos[0];
    s.ee_vel[0] = s.ee_vel[1] = 0;
    assert_int_equal(nds_state_set(&nm, d, &s, err, sizeof(err)), 0);
    mj_forward(nm.m, d);
    int nt = -1, ne = -1;
    nds_contacts(&nm, d, &nt, &ne);
    assert_int_equal(nt, 4);
    assert_int_equal(ne, i == 0 ? 1 : 0);
  }
  mj_deleteData(d);
  nds_model_free(&nm);
}

static void test_state_round_trip(void **state) {
  (void)state;
  nds_model nm;
  build_default(&nm);
  mjData *d = mj_makeData(nm.m);
  nds_state s = {
      .obj_pos = {0.12, -0.07, 0.031},
      .obj_quat = {2 * 0.9, 2 * 0.1, 2 * -0.2, 2 * 0.3}, /* not unit: set normalises */
      .obj_vel = {0.1, -0.2, 0.01, 0.5, -0.4, 1.5},
      .ee_pos = {-0.21, 0.33},
      .ee_vel = {0.4, -0.6},
  };
  char err[256];
  d->time = 7;
  assert_int_equal(nds_state_set(&nm, d, &s, err, sizeof(err)), 0);
  assert_near(d->time, 0, 0);
  nds_state g;
  nds_state_get(&nm, d, &g);
  double qn = sqrt(0.81 + 0.01 + 0.04 + 0.09);
  for (int i = 0; i < 3; i++) assert_near(g.obj_pos[i], s.obj_pos[i], 0);
  for (int i = 0; i < 4; i++) assert_near(g.obj_quat[i], s.obj_quat[i] / 2 / qn, 1e-15);
  for (int i = 0; i < 6; i++) assert_near(g.obj_vel[i], s.obj_vel[i], 0);
  for (int k = 0; k < 2; k++) {
    assert_near(g.ee_pos[k], s.ee_pos[k], 1e-15);
    assert_near(g.ee_vel[k], s.ee_vel[k], 0);
  }
  /* The sphere is where the state says, in the world. */
  mj_forward(nm.m, d);
  assert_near(d->xpos[3 * nm.ee_body + 0], s.ee_pos[0], 1e-15);
  assert_near(d->xpos[3 * nm.ee_body + 1], s.ee_pos[1], 1e-15);
  assert_near(d->xpos[3 * nm.ee_body + 2], nm.ee_height, 1e-15);

  /* Bad states are refused. */
  nds_state bad = s;
  bad.ee_vel[1] = NAN;
  assert_int_equal(nds_state_set(&nm, d, &bad, err, sizeof(err)), -1);
  assert_contains(err, "finite");
  bad = s;
  bad.obj_pos[0] = INFINITY;
  assert_int_equal(nds_state_set(&nm, d, &bad, err, sizeof(err)), -1);
  bad = s;
  memset(bad.obj_quat, 0, sizeof(bad.obj_quat));
  assert_int_equal(nds_state_set(&nm, d, &bad, err, sizeof(err)), -1);
  assert_contains(err, "quaternion");

  /* Resting states: box on the table at the given yaw, all still. */
  for (double yaw = -3.0; yaw < 3.1; yaw += 0.75) {
    const double ee[2] = {0.5, -0.5};
    nds_state_rest(&nm, 0.2, 0.1, yaw, ee, &g);
    assert_near(nds_state_yaw(&g), yaw, 1e-12);
    assert_near(g.obj_pos[2], nm.cfg.obj_half[2], 0);
    assert_near(g.ee_pos[0], 0.5, 0);
    assert_near(g.ee_vel[0] + g.obj_vel[5], 0, 0);
  }
  mj_deleteData(d);
  nds_model_free(&nm);
}

/* Write text to a fresh temporary .xml file; path receives its name. */
static void write_tmp(const char *text, char path[64]) {
  strcpy(path, "/tmp/nudge_test_model_XXXXXX.xml");
  int fd = mkstemps(path, 4);
  assert_true(fd >= 0);
  FILE *f = fdopen(fd, "w");
  assert_non_null(f);
  fputs(text, f);
  fclose(f);
}

/* Replace the first occurrence of from by to (same length) in s. */
static void patch(char *s, const char *from, const char *to) {
  char *p = strstr(s, from);
  assert_non_null(p);
  assert_int_equal(strlen(from), strlen(to));
  memcpy(p, to, strlen(to));
}

/* A box whose geom sits at its inertial frame (a file's, MuJoCo marks the geom sameframe
 * 2): shifting the centre of mass must not carry the geom along, and unshifting gives the
 * model as loaded, bit for bit. */
static void test_theta_box_geom_at_iframe(void **state) {
  (void)state;
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  cfg.obj_com[0] = 0.01;
  char xml[4096], out[4200], err[512], path[64];
  assert_int_equal(nds_scene_xml(&cfg, xml, sizeof(xml), err, sizeof(err)), 0);
  const char *mark = "<geom name=\"object\" type=\"box\"";
  char *at = strstr(xml, mark);
  assert_non_null(at);
  snprintf(out, sizeof(out), "%.*s<geom name=\"object\" pos=\"0.01 0 0\" type=\"box\"%s",
           (int)(at - xml), xml, at + strlen(mark));
  write_tmp(out, path);
  nds_model a, b;
  if (nds_model_load_file(&a, path, &cfg, err, sizeof(err))) fail_msg("%s", err);
  if (nds_model_load_file(&b, path, &cfg, err, sizeof(err))) fail_msg("%s", err);
  unlink(path);
  int g = mj_name2id(a.m, mjOBJ_GEOM, "object");
  assert_int_equal(a.m->geom_sameframe[g], 2);
  double th[ND_NTHETA];
  memcpy(th, nd_theta_true, sizeof(th));
  th[ND_TH_COM_X] = -0.005, th[ND_TH_COM_Y] = 0.004;
  assert_int_equal(nds_theta_apply(&a, th, err, sizeof(err)), 0);
  mjData *d = mj_makeData(a.m);
  mj_forward(a.m, d);
  const int o = a.obj_body;
  assert_near(d->geom_xpos[3 * g + 0] - d->xpos[3 * o + 0], 0.01, 1e-12);  /* not moved */
  assert_near(d->geom_xpos[3 * g + 1] - d->xpos[3 * o + 1], 0, 1e-12);
  assert_near(d->xipos[3 * o + 0] - d->xpos[3 * o + 0], 0.005, 1e-12);    /* the mass is */
  assert_near(d->xipos[3 * o + 1] - d->xpos[3 * o + 1], 0.004, 1e-12);
  mj_deleteData(d);
  memcpy(th, nd_theta_true, sizeof(th));
  assert_int_equal(nds_theta_apply(&a, th, err, sizeof(err)), 0);
  const mjModel *ma = a.m, *mb = b.m;
  assert_memory_equal(ma->geom_sameframe, mb->geom_sameframe, ma->ngeom);
  assert_memory_equal(ma->body_sameframe, mb->body_sameframe, ma->nbody);
  assert_memory_equal(ma->body_simple, mb->body_simple, ma->nbody);
  assert_memory_equal(ma->dof_simplenum, mb->dof_simplenum, sizeof(int) * ma->nv);
  assert_memory_equal(ma->body_ipos, mb->body_ipos, sizeof(mjtNum) * 3 * ma->nbody);
  assert_memory_equal(ma->dof_invweight0, mb->dof_invweight0, sizeof(mjtNum) * ma->nv);
  nds_model_free(&a);
  nds_model_free(&b);
}

static void test_load_file(void **state) {
  (void)state;
  nds_scene_cfg cfg;
  nds_scene_cfg_default(&cfg);
  cfg.timestep = 0.004;
  cfg.condim = 4;
  cfg.obj_half[0] = 0.07;
  char xml[4096], err[512], path[64];
  assert_int_equal(nds_scene_xml(&cfg, xml, sizeof(xml), err, sizeof(err)), 0);

  nds_model a, f;
  build(&a, &cfg);
  write_tmp(xml, path);
  nds_scene_cfg fcfg;
  nds_scene_cfg_default(&fcfg); /* other sizes: the file's must win */
  fcfg.theta[ND_TH_SLIDE] = 0.4;
  if (nds_model_load_file(&f, path, &fcfg, err, sizeof(err))) fail_msg("%s", err);
  unlink(path);
  assert_int_equal(f.obj_qpos, a.obj_qpos);
  assert_int_equal(f.ee_qpos[1], a.ee_qpos[1]);
  assert_int_equal(f.ee_dof[0], a.ee_dof[0]);
  assert_near(f.ee_height, a.ee_height, 0);
  assert_near(f.cfg.timestep, 0.004, 0);
  assert_near(f.cfg.obj_half[0], 0.07, 0);
  assert_int_equal(f.cfg.condim, 4);
  assert_near(f.cfg.tilt_damping, 0, 0); /* MJCF cannot say it; the file has none */
  assert_near(f.m->geom_friction[0], 0.4, 0);
  nds_model_free(&a);
  nds_model_free(&f);

  /* A missing file is named. */
  const char *missing = "/nonexistent/nudge/scene.xml";
  assert_int_equal(nds_model_load_file(&f, missing, &cfg, err, sizeof(err)), -1);
  assert_null(f.m);
  assert_contains(err, missing);

  /* Malformed XML (cut short, not XML at all, an unknown element) is refused with the
   * file's name and the parser's reason. */
  struct {
    size_t keep;       /* bytes of the good file kept; 0: text instead */
    const char *text, *what;
  } junk[] = {
      {200, NULL, "XML"},
      {0, "this is not MJCF\n", "XML"},
      {0, "<mujoco><worldbody><bogus/></worldbody></mujoco>", "bogus"},
      {0, "", "XML"},
  };
  for (size_t i = 0; i < sizeof(junk) / sizeof(junk[0]); i++) {
    char bad[4096];
    if (junk[i].keep) {
      memcpy(bad, xml, junk[i].keep);
      bad[junk[i].keep] = 0;
    } else {
      strcpy(bad, junk[i].text);
    }
    write_tmp(bad, path);
    err[0] = 0;
    assert_int_equal(nds_model_load_file(&f, path, &cfg, err, sizeof(err)), -1);
    unlink(path);
    assert_null(f.m);
    assert_contains(err, path);
    assert_contains(err, junk[i].what);
  }

  /* Missing parts are named with the file. */
  struct {
    const char *from, *to, *from2, *to2, *what;
  } cut[] = {
      {"name=\"ee_y\"", "name=\"ee_z\"", NULL, NULL, "no joint named \"ee_y\""},
      {"name=\"object\" pos", "name=\"objekt\" pos", NULL, NULL, "no body named \"object\""},
      /* the contact exclusion names the sphere body too: point it elsewhere */
      {"body name=\"ee\"", "body name=\"EE\"", "body2=\"ee\"", "body2=\"EE\"",
       "no body named \"ee\""},
      {"type=\"slide\" axis=\"1 0 0\"", "type=\"slide\" axis=\"0 1 0\"", NULL, NULL,
       "\"ee_x\" must be"},
  };
  for (size_t i = 0; i < sizeof(cut) / sizeof(cut[0]); i++) {
    char bad[4096];
    strcpy(bad, xml);
    patch(bad, cut[i].from, cut[i].to);
    if (cut[i].from2) patch(bad, cut[i].from2, cut[i].to2);
    write_tmp(bad, path);
    err[0] = 0;
    assert_int_equal(nds_model_load_file(&f, path, &cfg, err, sizeof(err)), -1);
    unlink(path);
    assert_null(f.m);
    assert_contains(err, path);
    assert_contains(err, cut[i].what);
  }
}

static void test_ctrl(void **state) {
  (void)state;
  nds_ctrl_cfg cfg;
  nds_ctrl_cfg_default(&cfg);
  nds_ctrl c;
  nds_ctrl_reset(&c, NDS_CTRL_M_REF);
  const double sp[2][4] = {{0.01, 0.1, 2.0, 0}, {-0.002, 0, -1.0, 0}};
  const double pos[2] = {0, 0}, vel[2] = {0.05, 0.02}, dt = 0.002;
  double f[2];
  nds_ctrl_pid(&cfg, &c, sp, pos, vel, dt, f);
  assert_near(f[0], cfg.m_ff * 2.0 + cfg.kp * 0.01 + cfg.kd * 0.05 + cfg.ki * 0.01 * dt, 1e-12);
  assert_near(f[1], -cfg.m_ff + cfg.kp * -0.002 + cfg.kd * -0.02 + cfg.ki * -0.002 * dt, 1e-12);
  /* The integral winds up to i_max and no further; the force saturates at f_max. */
  for (int i = 0; i < 10000; i++) nds_ctrl_pid(&cfg, &c, sp, pos, vel, dt, f);
  assert_near(c.integ[0], cfg.i_max, 0);
  assert_near(c.integ[1], -cfg.i_max, 0);
  const double far[2][4] = {{1.0, 0, 0, 0}, {-1.0, 0, 0, 0}};
  nds_ctrl_pid(&cfg, &c, far, pos, vel, dt, f);
  assert_near(f[0], cfg.f_max, 0);
  assert_near(f[1], -cfg.f_max, 0);
  /* A bad input shows as a bad force, not as a quietly saturated one. */
  const double nan_sp[2][4] = {{NAN, 0, 0, 0}, {0, 0, 0, 0}};
  nds_ctrl_reset(&c, NDS_CTRL_M_REF);
  nds_ctrl_pid(&cfg, &c, nan_sp, pos, vel, dt, f);
  assert_true(isnan(f[0]));

  const double vref[2] = {0.3, -10};
  nds_ctrl_vel(&cfg, &c, vref, vel, f);
  assert_near(f[0], cfg.kv * 0.25, 1e-12);
  assert_near(f[1], -cfg.f_max, 0);

  /* A sphere of 3 kg: every force and the bound three times as large. */
  double f1[2];
  nds_ctrl_reset(&c, NDS_CTRL_M_REF);
  nds_ctrl_pid(&cfg, &c, sp, pos, vel, dt, f1);
  nds_ctrl_reset(&c, 3.0 * NDS_CTRL_M_REF);
  nds_ctrl_pid(&cfg, &c, sp, pos, vel, dt, f);
  assert_near(f[0], 3.0 * f1[0], 1e-9 * fabs(f1[0]));
  nds_ctrl_vel(&cfg, &c, vref, vel, f);
  assert_near(f[0], 3.0 * cfg.kv * 0.25, 1e-12);
  assert_near(f[1], -3.0 * cfg.f_max, 0);
}

/* The stability claim of the default gains, on the controller alone: a point mass under
 * semi-implicit Euler settles from a 1 cm error at m = 0.2 kg, dt = 10 ms, and at the
 * nominal 1 kg; at half the supported mass the same gains go unstable, so the bound the
 * defaults were chosen by is real and not far from where they sit. */
static double settle_error(double m, double dt, double seconds) {
  nds_ctrl_cfg cfg;
  nds_ctrl_cfg_default(&cfg);
  cfg.m_ff = m;
  cfg.f_max = INFINITY; /* the linear loop: saturation would cap an unstable one */
  nds_ctrl c;
  nds_ctrl_reset(&c, NDS_CTRL_M_REF);
  const double sp[2][4] = {{0.01, 0, 0, 0}, {0, 0, 0, 0}};
  double x[2] = {0, 0}, v[2] = {0, 0}, f[2];
  int n = (int)lround(seconds / dt);
  for (int i = 0; i < n; i++) {
    nds_ctrl_pid(&cfg, &c, sp, x, v, dt, f);
    for (int k = 0; k < 2; k++) {
      v[k] += dt * f[k] / m;
      x[k] += dt * v[k];
    }
  }
  return fabs(x[0] - 0.01) + fabs(x[1]);
}

static void test_ctrl_stability_bound(void **state) {
  (void)state;
  /* The integral's slow pole (kp / ki = 0.5 s) sets the pace; the 5 kg sphere rings
   * (damping ratio 0.14) but decays. */
  assert_true(settle_error(0.2, 0.01, 5.0) < 1e-6);
  assert_true(settle_error(0.2, 0.005, 5.0) < 1e-6);
  assert_true(settle_error(1.0, 0.01, 5.0) < 1e-6);
  assert_true(settle_error(5.0, 0.001, 5.0) < 2e-4);
  double e = settle_error(0.1, 0.01, 2.0);
  printf("pid_error_0.1kg_10ms %.3g m\n", e);
  assert_true(!(e < 1.0)); /* diverged */
}

int main(void) {
  nds_test_catch_warnings();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_default_scene),
      cmocka_unit_test(test_bad_cfg_rejected),
      cmocka_unit_test(test_bad_theta_rejected),
      cmocka_unit_test(test_theta_parse),
      cmocka_unit_test(test_theta_apply_matches_build),
      cmocka_unit_test(test_theta_box_matches_build),
      cmocka_unit_test(test_theta_apply_idempotent),
      cmocka_unit_test(test_copy_is_independent),
      cmocka_unit_test(test_mass_changes_response),
      cmocka_unit_test(test_rest_is_stable),
      cmocka_unit_test(test_contacts_by_pair),
      cmocka_unit_test(test_state_round_trip),
      cmocka_unit_test(test_load_file),
      cmocka_unit_test(test_theta_box_geom_at_iframe),
      cmocka_unit_test(test_ctrl),
      cmocka_unit_test(test_ctrl_stability_bound),
  };
  int rc = cmocka_run_group_tests(tests, NULL, NULL);
  if (nds_test_warnings) {
    fprintf(stderr, "MuJoCo printed %d warnings\n", nds_test_warnings);
    rc = 1;
  }
  return rc;
}
