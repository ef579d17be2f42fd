/* test_rollout: single and batched rollouts: tracking, contact physics under theta,
 * determinism across workers and histories, divergence handling. */
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"
#include "nd_rng.h"
#include "nd_snap.h"
#include "nd_stats.h"
#include "nd_test.h"
#include "nds_test.h"
#include "nds_rollout.h"

/* Setpoint state at rest at (x, y). */
static void sp_at(double x, double y, double sp[2][4]) {
  memset(sp, 0, 8 * sizeof(double));
  sp[0][ND_P] = x;
  sp[1][ND_P] = y;
}

/* The test model at step dt with theta th (NULL: the truth), its mjData, and the default
 * controller in ctrl; close_model frees both. */
static mjData *open_model(nds_model *nm, double dt, const double *th, nds_ctrl_cfg *ctrl) {
  nds_test_build(nm, dt, th);
  nds_ctrl_cfg_default(ctrl);
  return mj_makeData(nm->m);
}

static void close_model(nds_model *nm, mjData *d) {
  mj_deleteData(d);
  nds_model_free(nm);
}

/* The sphere away from the box: a two-keypoint move ending at rest. */
static const double free_keys[8] = {-0.2, 0.25, 0.3, 0.1, -0.1, 0.2, 0, 0};

static void free_start(const nds_model *nm, nds_state *s, double sp[2][4]) {
  const double ee[2] = {-0.3, 0.2};
  nds_state_rest(nm, 0, 0, 0, ee, s);
  sp_at(ee[0], ee[1], sp);
}

/* The rollout follows the chained segments: ends at the last keypoint, reports the
 * setpoint's acceleration and peaks as an independent evaluation of the chain gives
 * them, and runs round(M T / dt) steps. */
static void test_tracks_keypoints(void **state) {
  (void)state;
  const double dts[4] = {0.001, 0.002, 0.005, 0.01};
  for (int i = 0; i < 4; i++) {
    nds_model nm;
    nds_ctrl_cfg ctrl;
    mjData *d = open_model(&nm, dts[i], NULL, &ctrl);
    nds_state s0;
    double sp0[2][4];
    free_start(&nm, &s0, sp0);
    nds_rollout_out o;
    nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
    assert_int_equal(o.diverged, 0);
    printf("ee_final_error_%gms %.2e m\n", dts[i] * 1e3,
           hypot(o.ee_xy[0] + 0.1, o.ee_xy[1] - 0.2));
    assert_near(o.ee_xy[0], -0.1, 1e-3);
    assert_near(o.ee_xy[1], 0.2, 1e-3);
    assert_near(o.obj_xy[0], 0, 1e-4); /* untouched */
    assert_near(o.obj_yaw, 0, 1e-4);

    long n = lround(0.6 / dts[i]);
    assert_near(d->time, n * dts[i], 1e-9);
    nd_snap_seg seg[2];
    double s[2][4];
    memcpy(s, sp0, sizeof(s));
    for (int k = 0; k < 2; k++) {
      nd_snap_seg_make(&seg[k], (const double(*)[4])s, free_keys + 4 * k, free_keys + 4 * k + 2, 0.3);
      nd_snap_seg_eval(&seg[k], 0.3, s);
    }
    double acc = 0, vpk = 0, apk = 0;
    for (long j = 0; j < n; j++) {
      double t = j * dts[i];
      int k = t < 0.3 ? 0 : 1;
      nd_snap_seg_eval(&seg[k], t - 0.3 * k, s);
      double a = hypot(s[0][ND_A], s[1][ND_A]), v = hypot(s[0][ND_V], s[1][ND_V]);
      acc += a * a;
      vpk = fmax(vpk, v);
      apk = fmax(apk, a);
    }
    assert_near(o.acc_sq_mean, acc / n, 1e-9 * acc / n);
    assert_near(o.v_peak, vpk, 1e-12);
    assert_near(o.a_peak, apk, 1e-12);
    close_model(&nm, d);
  }

  /* A duration that is not a whole number of steps rounds to the nearest. */
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.007, NULL, &ctrl);
  nds_state s0;
  double sp0[2][4];
  free_start(&nm, &s0, sp0);
  nds_rollout_out o;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 0);
  assert_near(d->time, 86 * 0.007, 1e-12); /* round(0.6 / 0.007) = 86 */
  close_model(&nm, d);
}

/* The lightest supported sphere at the coarsest supported step still tracks. */
static void test_light_sphere_coarse_step(void **state) {
  (void)state;
  const double th[ND_NTHETA] = {1, 0.005, 1e-4, 0.2, 1, 0, 0};
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.01, th, &ctrl);
  nds_state s0;
  double sp0[2][4];
  free_start(&nm, &s0, sp0);
  nds_rollout_out o;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 0);
  assert_near(o.ee_xy[0], -0.1, 2e-3);
  assert_near(o.ee_xy[1], 0.2, 2e-3);
  close_model(&nm, d);
}

/* The sphere at rest 10 cm behind the box (at the origin) on the x axis, its setpoint
 * there too. */
static void behind_start(const nds_model *nm, nds_state *s, double sp[2][4]) {
  const double ee[2] = {-0.1, 0};
  nds_state_rest(nm, 0, 0, 0, ee, s);
  sp_at(ee[0], ee[1], sp);
}

/* Theta reaches the contact: the sphere strikes the box and stops, the box slides on;
 * it slides less far under more sliding friction. */
static double push_distance(double slide) {
  const double th[ND_NTHETA] = {slide, 0.005, 1e-4, 1.0, 1, 0, 0};
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.001, th, &ctrl);
  nds_state s0;
  double sp0[2][4];
  behind_start(&nm, &s0, sp0);
  const double keys[12] = {-0.03, 0, 0.8, 0, 0.0, 0, 0, 0, 0.0, 0, 0, 0};
  nds_rollout_out o;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 3, 0.2, &o);
  assert_int_equal(o.diverged, 0);
  assert_near(o.obj_xy[1], 0, 1e-3); /* straight push */
  assert_near(o.obj_yaw, 0, 1e-2);
  assert_near(o.ee_xy[0], 0, 5e-3); /* the integral still unwinds what the push wound up */
  assert_true(fabs(d->qvel[0]) < 1e-3); /* the box has come to rest */
  close_model(&nm, d);
  return o.obj_xy[0];
}

static void test_friction_changes_push(void **state) {
  (void)state;
  double lo = push_distance(0.5), hi = push_distance(1.5);
  printf("push_distance_mu0.5 %.4f m\npush_distance_mu1.5 %.4f m\n", lo, hi);
  /* Both were pushed past where the sphere stopped (its front at x = 0.025, the box's
   * back face starting at -0.05: 0.075 m of contact travel). */
  assert_true(hi > 0.07);
  assert_true(lo > hi + 0.02);
}

/* The object's poses and the sphere's positions along the horizon: the last are the final
 * ones, a sample where a segment ends is where a rollout of the segments up to it ends,
 * and a straight push never moves either back. */
static void test_samples_along_horizon(void **state) {
  (void)state;
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.001, NULL, &ctrl);
  nds_state s0;
  double sp0[2][4];
  behind_start(&nm, &s0, sp0);
  const double keys[8] = {-0.02, 0, 0.6, 0, 0.05, 0, 0, 0};
  nds_rollout_out full, first;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &full);
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 1, 0.3, &first);
  assert_int_equal(full.diverged, 0);
  assert_int_equal(first.diverged, 0);
  const int last = NDS_ROLLOUT_NS - 1, half = NDS_ROLLOUT_NS / 2 - 1;
  assert_true(full.obj_at[last][0] == full.obj_xy[0] && full.obj_at[last][1] == full.obj_xy[1]);
  assert_true(full.obj_at[last][2] == full.obj_yaw);
  /* 600 steps, 8 samples: the fourth falls at step 300, where the first segment ends. */
  assert_true(full.obj_at[half][0] == first.obj_xy[0] && full.obj_at[half][1] == first.obj_xy[1]);
  assert_true(full.obj_at[half][2] == first.obj_yaw);
  assert_true(full.ee_at[last][0] == full.ee_xy[0] && full.ee_at[last][1] == full.ee_xy[1]);
  assert_true(full.ee_at[half][0] == first.ee_xy[0] && full.ee_at[half][1] == first.ee_xy[1]);
  for (int k = 1; k < NDS_ROLLOUT_NS; k++) {
    assert_true(full.obj_at[k][0] >= full.obj_at[k - 1][0]);
    assert_true(full.ee_at[k][0] > full.ee_at[k - 1][0]);
  }
  printf("sampled_object_x %.4f %.4f %.4f m (first, mid, last)\n", full.obj_at[0][0],
         full.obj_at[half][0], full.obj_at[last][0]);
  assert_true(full.obj_at[last][0] > full.obj_at[0][0] + 0.02);
  close_model(&nm, d);
}

/* Rollouts from the same state and plan are bitwise identical on every worker, in a
 * batch, and whatever ran on the mjData before. */
static void test_deterministic(void **state) {
  (void)state;
  char err[256];
  nd_pool *pool = nd_pool_create(2, err, sizeof(err));
  assert_non_null(pool);
  nds_model proto;
  nds_test_build(&proto, 0.005, NULL);
  nds_batch *b = nds_batch_create(&proto, pool, err, sizeof(err));
  assert_non_null(b);
  assert_ptr_equal(nds_batch_pool(b), pool);
  nds_ctrl_cfg ctrl;
  nds_ctrl_cfg_default(&ctrl);

  /* A push with an offset on a box already sliding and turning, so the contact solver
   * works on the cone's boundary, where its result depends on where it starts. */
  nds_state s0;
  const double ee[2] = {-0.1, 0.015};
  nds_state_rest(&proto, 0, 0, 0.1, ee, &s0);
  s0.obj_vel[0] = 0.15;
  s0.obj_vel[1] = 0.05;
  s0.obj_vel[5] = 0.5;
  s0.obj_pos[2] -= 1e-4; /* sunk in as a synced box is, so the first step has contacts */
  double sp0[2][4];
  sp_at(ee[0], ee[1], sp0);
  const double keys[8] = {-0.04, 0.02, 0.3, 0.0, 0.02, 0.0, 0.1, -0.1};

  nds_rollout_out ref, o;
  nds_rollout(nds_batch_model(b, 0), nds_batch_data(b, 0), &ctrl, &s0,
              (const double(*)[4])sp0, keys, 2, 0.3, &ref);
  assert_int_equal(ref.diverged, 0);
  printf("offset_push_obj %.4f %.4f m yaw %.4f rad\n", ref.obj_xy[0], ref.obj_xy[1], ref.obj_yaw);
  assert_true(ref.obj_xy[0] > 0.02);
  assert_true(fabs(ref.obj_yaw - 0.1) > 0.01);
  nds_rollout(nds_batch_model(b, 1), nds_batch_data(b, 1), &ctrl, &s0,
              (const double(*)[4])sp0, keys, 2, 0.3, &o);
  assert_memory_equal(&ref, &o, sizeof(o));

  /* Dirty worker 0's mjData: a diverging rollout, a rollout that ends mid-push (the
   * solver's warm start then comes from another contact state), stray inputs. */
  mjData *d = nds_batch_data(b, 0);
  const nds_model *nm = nds_batch_model(b, 0);
  nds_ctrl_cfg wild = ctrl;
  wild.kp = 1e9;
  wild.f_max = INFINITY;
  nds_rollout(nm, d, &wild, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  nds_state other = s0;
  other.obj_vel[0] = 0.3;
  other.obj_vel[5] = -1.0;
  nds_rollout(nm, d, &ctrl, &other, (const double(*)[4])sp0, keys, 1, 0.3, &o);
  assert_int_equal(o.diverged, 0);
  /* A mild stray warm start: one the solver prefers to its own start, so it counts. */
  for (int i = 0; i < nm->m->nv; i++) d->qacc_warmstart[i] = 0.3 * i;
  for (int i = 0; i < nm->m->nv; i++) d->qfrc_applied[i] = 0.5;
  for (int i = 0; i < 6 * nm->m->nbody; i++) d->xfrc_applied[i] = 0.1;
  d->time = 42;
  nds_rollout(nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &o);
  assert_memory_equal(&ref, &o, sizeof(o));

  /* A batch of the same plan and of mixed plans, against serial rollouts on a copy. */
  enum { N = 12 };
  double bk[N * 8];
  nds_rollout_out bo[N], so;
  for (int i = 0; i < N; i++) {
    memcpy(bk + 8 * i, keys, sizeof(keys));
    if (i % 3) bk[8 * i + 1] += 0.004 * i, bk[8 * i + 6] -= 0.02 * i;
  }
  nds_batch_rollouts(b, &ctrl, &s0, (const double(*)[4])sp0, bk, N, 2, 0.3, bo);
  nds_model serial;
  assert_int_equal(nds_model_copy(&serial, &proto, err, sizeof(err)), 0);
  mjData *sd = mj_makeData(serial.m);
  for (int i = 0; i < N; i++) {
    nds_rollout(&serial, sd, &ctrl, &s0, (const double(*)[4])sp0, bk + 8 * i, 2, 0.3, &so);
    assert_memory_equal(&so, &bo[i], sizeof(so));
    if (i % 3 == 0) assert_memory_equal(&ref, &bo[i], sizeof(so));
  }
  assert_true(bo[1].obj_xy[1] != bo[2].obj_xy[1]);

  /* theta for the whole batch, checked before any model changes. */
  const double bad[ND_NTHETA] = {1, 0.005, 1e-4, NAN, 1, 0, 0};
  assert_int_equal(nds_batch_set_theta(b, bad, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "sphere mass"));
  assert_near(nds_batch_model(b, 1)->m->body_mass[proto.ee_body], 1.0, 0);
  const double th[ND_NTHETA] = {0.6, 0.005, 1e-4, 0.7, 1, 0, 0};
  assert_int_equal(nds_batch_set_theta(b, th, err, sizeof(err)), 0);
  for (int w = 0; w < 2; w++) {
    assert_near(nds_batch_model(b, w)->m->body_mass[proto.ee_body], 0.7, 0);
    assert_near(nds_batch_model(b, w)->m->geom_friction[0], 0.6, 0);
  }
  nds_batch_rollouts(b, &ctrl, &s0, (const double(*)[4])sp0, bk, 1, 2, 0.3, bo);
  assert_true(memcmp(&bo[0], &ref, sizeof(ref)) != 0);

  mj_deleteData(sd);
  nds_model_free(&serial);
  nds_batch_free(b);
  nds_model_free(&proto);
  nd_pool_free(pool);
}

/* Bad inputs and numerical blow-ups come back as diverged = 1, quietly, and leave the
 * mjData fit for the next rollout. */
static void test_divergence(void **state) {
  (void)state;
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.01, NULL, &ctrl);
  nds_state s0;
  double sp0[2][4];
  free_start(&nm, &s0, sp0);
  nds_rollout_out good, o;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &good);
  assert_int_equal(good.diverged, 0);

  nds_state bad = s0;
  bad.obj_quat[2] = NAN;
  nds_rollout(&nm, d, &ctrl, &bad, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  double kb[8];
  memcpy(kb, free_keys, sizeof(kb));
  kb[5] = NAN;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, kb, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  double spb[2][4];
  memcpy(spb, sp0, sizeof(spb));
  spb[1][ND_J] = INFINITY;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])spb, free_keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.0, &o);
  assert_int_equal(o.diverged, 1);
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 0, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, ND_MAX_KEYS + 1, 0.3, &o);
  assert_int_equal(o.diverged, 1);

  /* Gains far beyond the explicit-integration bound. */
  nds_ctrl_cfg wild = ctrl;
  wild.kp = 1e9;
  wild.kd = 0;
  wild.f_max = INFINITY;
  nds_rollout(&nm, d, &wild, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  /* Keypoints a million kilometres off, with no force limit to save the day. */
  double kfar[8] = {1e9, -1e9, 1e9, 1e9, 1e9, 1e9, 0, 0};
  nds_ctrl_cfg unsat = ctrl;
  unsat.f_max = INFINITY;
  nds_rollout(&nm, d, &unsat, &s0, (const double(*)[4])sp0, kfar, 2, 0.3, &o);
  assert_int_equal(o.diverged, 1);
  /* With the default saturation the same plan is merely far: finite and reported. */
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, kfar, 2, 0.3, &o);
  assert_int_equal(o.diverged, 0);
  assert_true(isfinite(o.ee_xy[0]) && o.ee_xy[0] > 1.0);
  assert_true(o.v_peak > 1e9);

  /* The mjData that diverged still gives the clean result. */
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, free_keys, 2, 0.3, &o);
  assert_memory_equal(&good, &o, sizeof(o));
  assert_int_equal(nds_test_warnings, 0);
  close_model(&nm, d);
}

/* Free flight changes no outcome: 96 random plans from starts far from, near and touching
 * the box, at the planner's 10 ms and 5 ms steps, end with the object and the sphere where
 * full MuJoCo steps put them (within 10 um, far below motion capture's 0.1 mm), and skip
 * steps only while the sphere is out of reach. */
static void test_free_flight_agrees(void **state) {
  (void)state;
  const double dts[2] = {0.01, 0.005};
  const double starts[3][2] = {{-0.30, 0.20}, {-0.12, 0.0}, {-0.076, 0.0}};
  uint64_t rng = 99;
  double worst_obj = 0, worst_ee = 0;
  long skipped = 0, steps = 0, far_skipped = 0, far_steps = 0;
  for (int k = 0; k < 2; k++) {
    nds_model nm;
    nds_ctrl_cfg ctrl;
    mjData *d = open_model(&nm, dts[k], NULL, &ctrl);
    for (int i = 0; i < 48; i++) {
      const double *e = starts[i % 3];
      nds_state s0;
      double sp0[2][4], keys[8];
      nds_state_rest(&nm, 0, 0, 0, e, &s0);
      sp_at(e[0], e[1], sp0);
      for (int j = 0; j < 8; j++) {
        rng = rng * 6364136223846793005ULL + 1442695040888963407ULL;
        const double u = (double)(rng >> 11) / 9007199254740992.0 - 0.5;
        keys[j] = j % 4 < 2 ? e[j % 4] + 0.4 * u : 0.6 * u;
      }
      nds_rollout_out full, ff;
      nds_rollout_ff(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, 0, &full);
      nds_rollout_ff(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, 1, &ff);
      assert_int_equal(full.diverged, 0);
      assert_int_equal(ff.diverged, 0);
      assert_int_equal(full.skipped, 0);
      worst_obj = fmax(worst_obj, hypot(ff.obj_xy[0] - full.obj_xy[0], ff.obj_xy[1] - full.obj_xy[1]));
      worst_obj = fmax(worst_obj, 0.05 * fabs(nd_wrap_angle(ff.obj_yaw - full.obj_yaw)));
      for (int s = 0; s < NDS_ROLLOUT_NS; s++) {
        const double *a = ff.obj_at[s], *b = full.obj_at[s];
        worst_obj = fmax(worst_obj, fmax(hypot(a[0] - b[0], a[1] - b[1]),
                                         0.05 * fabs(nd_wrap_angle(a[2] - b[2]))));
      }
      worst_ee = fmax(worst_ee, hypot(ff.ee_xy[0] - full.ee_xy[0], ff.ee_xy[1] - full.ee_xy[1]));
      for (int s = 0; s < NDS_ROLLOUT_NS; s++)
        worst_ee = fmax(worst_ee, hypot(ff.ee_at[s][0] - full.ee_at[s][0],
                                        ff.ee_at[s][1] - full.ee_at[s][1]));
      skipped += ff.skipped, steps += ff.steps;
      if (i % 3 == 0) far_skipped += ff.skipped, far_steps += ff.steps;
      if (i % 3 == 2) assert_true(ff.skipped < ff.steps);
    }
    close_model(&nm, d);
  }
  printf("free_flight_worst_object %.2e m\nfree_flight_worst_sphere %.2e m\n", worst_obj, worst_ee);
  printf("free_flight_skipped %.3f of steps (from far: %.3f)\n", (double)skipped / steps,
         (double)far_skipped / far_steps);
  assert_true(worst_obj < 1e-5);
  assert_true(worst_ee < 1e-5);
  assert_true(far_skipped > far_steps / 2);
}

/* The 10 ms planning model with its calibrated contact (nds_scene_cfg_planning) predicts
 * the 1 ms world's pushes, from all sides of a yawed box, to under 1 cm (median; ~8 mm in
 * nudge-calibrate's check, the world's own contact at 10 ms ~15 mm) and clearly better
 * than the world's contact at that step; other steps keep the world's contact. */
static void test_planning_contact(void **state) {
  (void)state;
  char err[256];
  nds_scene_cfg c5, def;
  nds_scene_cfg_default(&def);
  assert_int_equal(nds_scene_cfg_planning(&c5, 0.005), 0);
  assert_near(c5.timestep, 0.005, 0.0);
  assert_near(c5.solref[0], def.solref[0], 0.0);
  assert_near(c5.tilt_damping, def.tilt_damping, 0.0);
  nds_scene_cfg cc;
  assert_int_equal(nds_scene_cfg_planning(&cc, 0.01), 1);
  nds_model world, coarse, cal;
  nds_test_build(&world, 0.001, NULL);
  nds_test_build(&coarse, 0.01, NULL);
  if (nds_model_init(&cal, &cc, err, sizeof(err))) fail_msg("nds_model_init: %s", err);
  mjData *d = mj_makeData(world.m);
  nds_ctrl_cfg ctrl;
  nds_ctrl_cfg_default(&ctrl);
  enum { N = 256 };
  double e_coarse[N], e_cal[N];
  nd_rng rng;
  nd_rng_seed(&rng, 7, 0);
  for (int i = 0; i < N; i++) {
    double u[4];
    for (int j = 0; j < 4; j++) u[j] = nd_rng_uniform(&rng);
    /* The sphere 8 cm out at a bearing, pushed through the box up to 2.5 cm off centre. */
    const double a = 2.0 * M_PI * u[0], dir = a + M_PI, lat = 0.05 * (u[1] - 0.5);
    const double reach = 0.06 + 0.1 * u[2], c = cos(dir), sn = sin(dir);
    const double ee[2] = {0.08 * cos(a), 0.08 * sin(a)};
    const double keys[8] = {-lat * sn - 0.04 * c, lat * c - 0.04 * sn, 0.3 * c, 0.3 * sn,
                            -lat * sn + reach * c, lat * c + reach * sn, 0, 0};
    nds_state s0;
    double sp0[2][4];
    nds_state_rest(&world, 0, 0, 2.0 * (u[3] - 0.5), ee, &s0);
    sp_at(ee[0], ee[1], sp0);
    nds_rollout_out w, o1, o2;
    nds_rollout(&world, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &w);
    nds_rollout(&coarse, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &o1);
    nds_rollout(&cal, d, &ctrl, &s0, (const double(*)[4])sp0, keys, 2, 0.3, &o2);
    assert_int_equal(w.diverged + o1.diverged + o2.diverged, 0);
    e_coarse[i] = hypot(o1.obj_xy[0] - w.obj_xy[0], o1.obj_xy[1] - w.obj_xy[1]);
    e_cal[i] = hypot(o2.obj_xy[0] - w.obj_xy[0], o2.obj_xy[1] - w.obj_xy[1]);
  }
  const double m_coarse = nd_quantile(e_coarse, N, 0.5), m_cal = nd_quantile(e_cal, N, 0.5);
  printf("planning_contact_err_10ms_world %.4f m\nplanning_contact_err_10ms_calibrated %.4f m\n",
         m_coarse, m_cal);
  assert_true(m_cal < 0.010);
  assert_true(m_cal < 0.7 * m_coarse);
  mj_deleteData(d);
  nds_model_free(&world);
  nds_model_free(&coarse);
  nds_model_free(&cal);
}

/* nds_predict steps exactly as a rollout does: given the setpoints of a rollout's pushing
 * segment, step by step, it ends in the rollout's state, bit for bit; zero steps leave the
 * state as it was; a non-finite setpoint is refused. */
static void test_predict(void **state) {
  (void)state;
  nds_model nm;
  nds_ctrl_cfg ctrl;
  mjData *d = open_model(&nm, 0.005, NULL, &ctrl);
  nds_state s0, s1, sr;
  const double ee[2] = {-0.08, 0.01};
  nds_state_rest(&nm, 0, 0, 0.1, ee, &s0);
  double sp0[2][4];
  sp_at(ee[0], ee[1], sp0);
  const double key[4] = {0.06, 0.02, 0.1, 0.0}, T = 0.4;
  nds_rollout_out o;
  nds_rollout(&nm, d, &ctrl, &s0, (const double(*)[4])sp0, key, 1, T, &o);
  assert_false(o.diverged);
  assert_true(o.obj_xy[0] > 0.03);  /* it pushed */
  nds_state_get(&nm, d, &sr);

  enum { N = 80 };  /* T / dt */
  static double sp[N][2][4];
  nd_snap_seg seg;
  nd_snap_seg_make(&seg, (const double(*)[4])sp0, key, key + 2, T);
  for (int i = 0; i < N; i++) nd_snap_seg_eval(&seg, i * 0.005, sp[i]);
  char err[128];
  assert_int_equal(nds_predict(&nm, d, &ctrl, &s0, (const double(*)[2][4])sp, N, &s1, err,
                               sizeof err), 0);
  assert_memory_equal(&s1, &sr, sizeof s1);

  assert_int_equal(nds_predict(&nm, d, &ctrl, &s0, (const double(*)[2][4])sp, 0, &s1, err,
                               sizeof err), 0);
  for (int k = 0; k < 3; k++) assert_near(s1.obj_pos[k], s0.obj_pos[k], 1e-12);
  for (int k = 0; k < 2; k++) assert_near(s1.ee_pos[k], s0.ee_pos[k], 1e-12);

  sp[5][1][ND_V] = NAN;
  assert_int_equal(nds_predict(&nm, d, &ctrl, &s0, (const double(*)[2][4])sp, N, &s1, err,
                               sizeof err), -1);
  assert_non_null(strstr(err, "not finite"));
  close_model(&nm, d);
}

int main(void) {
  nds_test_catch_warnings();
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_tracks_keypoints),
      cmocka_unit_test(test_light_sphere_coarse_step),
      cmocka_unit_test(test_friction_changes_push),
      cmocka_unit_test(test_samples_along_horizon),
      cmocka_unit_test(test_deterministic),
      cmocka_unit_test(test_divergence),
      cmocka_unit_test(test_free_flight_agrees),
      cmocka_unit_test(test_planning_contact),
      cmocka_unit_test(test_predict),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
