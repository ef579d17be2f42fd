/* The demo's goal-reaching run at reduced population: the planner, the executor logic and
 * the controller together must push the object to goals within the paper's time limit. */
#include "nd_test.h"

#include <stdlib.h>
#include <string.h>

#include "nds_episode.h"
#include "nds_tfx.h"

typedef nds_tfx fixture;

static int setup(void **state) {
  fixture *f = calloc(1, sizeof(*f));
  assert_non_null(f);
  nds_tfx_init(f, 3);
  *state = f;
  return 0;
}

static int teardown(void **state) {
  nds_tfx_free(*state);
  free(*state);
  return 0;
}

static void run(fixture *f, const nd_goal *g, nds_episode_out *o) {
  char err[256];
  nds_episode_cfg ec;
  nds_episode_cfg_default(&ec);
  const double ee0[2] = {-0.10, 0.0};
  nds_state start;
  nds_state_rest(&f->world, 0.0, 0.0, 0.0, ee0, &start);
  nds_planner_reset(f->planner);
  const nds_planner_cfg *pc = nds_planner_config(f->planner);
  int rc = nds_episode_run(&f->world, f->d, f->planner, &pc->ctrl, &ec, &start, g, NULL, NULL,
                           o, err, sizeof(err));
  if (rc) fail_msg("episode failed: %s", err);
  printf("goal (%.2f, %.2f, %.2f): reached %d at %.2f s, pos err %.4f m, yaw err %.3f rad, "
         "%d plans\n", g->x, g->y, g->yaw, o->reached, o->t_reached, o->pos_err, o->yaw_err,
         o->plans);
}

/* Three of the demo's goals (a straight push and pushes with a turn either way) are reached
 * at eps 1e-2 within 5 s at N 32, C 2, and the reported pose errors agree with it. */
static void test_reaches_goals(void **state) {
  fixture *f = *state;
  const nd_goal goals[3] = {{.x = 0.20, .y = 0.00, .yaw = 0.0}, {.x = 0.15, .y = 0.12, .yaw = 0.6}, {.x = 0.15, .y = -0.12, .yaw = -0.6}};
  for (int i = 0; i < 3; i++) {
    nds_episode_out o;
    run(f, &goals[i], &o);
    assert_int_equal(o.reached, 1);
    assert_true(o.t_reached > 0.0 && o.t_reached <= 5.0);
    assert_true(o.pos_err < 0.1);
    assert_true(o.plans >= (int)(o.t_end / 0.05));
  }
}

/* Same seed, same episode: two fresh planners with one seed give bitwise equal results. */
static void test_deterministic(void **state) {
  fixture *f = *state;
  const nd_goal g = {.x = 0.20, .y = 0.00, .yaw = 0.0};
  nds_episode_out o[2];
  char err[256];
  nds_planner_cfg cfg = *nds_planner_config(f->planner);
  nds_planner *keep = f->planner;
  for (int i = 0; i < 2; i++) {
    f->planner = nds_planner_create(&f->plan, &cfg, f->pool, err, sizeof(err));
    assert_non_null(f->planner);
    run(f, &g, &o[i]);
    nds_planner_free(f->planner);
  }
  f->planner = keep;
  assert_true(o[0].t_end == o[1].t_end);
  assert_true(o[0].pos_err == o[1].pos_err);
  assert_true(o[0].yaw_err == o[1].yaw_err);
  assert_int_equal(o[0].plans, o[1].plans);
}

/* A planner task at the lab's limits (0.45 m/s, 1.8 m/s^2, 0.6 s segments, N 20, C 2): the
 * object at rest at the origin, the sphere and its setpoint 10 cm behind it. */
static void lab_start(const fixture *f, nds_state *s, double sp0[2][4], nds_planner_cfg *cfg) {
  const double ee0[2] = {-0.10, 0.0};
  nds_state_rest(&f->world, 0.0, 0.0, 0.0, ee0, s);
  memset(sp0, 0, 8 * sizeof(double));
  sp0[0][0] = ee0[0], sp0[1][0] = ee0[1];
  *cfg = *nds_planner_config(f->planner);
  cfg->v_max = 0.45, cfg->a_max = 1.8, cfg->T = 0.6, cfg->pop = 20, cfg->iters = 2;
}

/* At the lab's limits (0.45 m/s, 1.8 m/s^2, 0.6 s segments) most draws from a cold start
 * break them. Redrawing those makes more of the population worth simulating: more
 * rollouts and a smaller share of penalised candidates per plan, and no redraw at all
 * when redraws is 0. Either way the best plan keeps to the limits. */
static void test_redraws(void **state) {
  fixture *f = *state;
  const nd_goal g = {.x = 0.10, .y = 0.10, .yaw = 0.5};
  nds_state s;
  double sp0[2][4];
  nds_plan out[2];
  char err[256];
  for (int v = 0; v < 2; v++) {
    nds_planner_cfg cfg;
    lab_start(f, &s, sp0, &cfg);
    cfg.redraws = v ? 8 : 0;
    nds_planner_cfg_fit_limits(&cfg);
    nds_planner *p = nds_planner_create(&f->plan, &cfg, f->pool, err, sizeof(err));
    assert_non_null(p);
    assert_int_equal(nds_planner_plan(p, &s, (const double(*)[4])sp0, &g, &out[v], err, sizeof(err)), 0);
    nds_planner_free(p);
    printf("redraws %d: %d evaluated, %d simulated, %d beyond the limits, %d redrawn, cost %g\n",
           v ? 8 : 0, out[v].evals, out[v].rollouts, out[v].over_limits, out[v].redrawn, out[v].cost);
    assert_true(out[v].cost < cfg.limit_penalty);
  }
  assert_int_equal(out[0].redrawn, 0);
  assert_true(out[1].redrawn > out[1].evals);
  assert_true(out[1].rollouts > out[0].rollouts + out[0].evals / 4);
  assert_true(out[1].over_limits * out[0].evals < out[0].over_limits * out[1].evals);
}

/* The limit checks and redraws run on the pool, so the plan is the same on 1 worker as on
 * 2; and the prediction the plan reports is the rollout of its best keypoints, not of
 * another candidate. */
static void test_plan_pool_and_prediction(void **state) {
  fixture *f = *state;
  const nd_goal g = {.x = 0.10, .y = 0.10, .yaw = 0.5};
  nds_state s;
  double sp0[2][4];
  nds_planner_cfg cfg;
  lab_start(f, &s, sp0, &cfg);
  cfg.redraws = 8;
  nds_planner_cfg_fit_limits(&cfg);
  char err[256];
  nd_pool *one = nd_pool_create(1, err, sizeof(err));
  assert_non_null(one);
  nds_plan out[2][3];
  for (int v = 0; v < 2; v++) {
    nds_planner *p = nds_planner_create(&f->plan, &cfg, v ? f->pool : one, err, sizeof(err));
    assert_non_null(p);
    for (int k = 0; k < 3; k++)  /* cold, then warm-started */
      assert_int_equal(nds_planner_plan(p, &s, (const double(*)[4])sp0, &g, &out[v][k], err, sizeof(err)), 0);
    nds_planner_free(p);
  }
  nd_pool_free(one);
  for (int k = 0; k < 3; k++) {
    assert_memory_equal(out[0][k].keys, out[1][k].keys, sizeof(double) * 4 * cfg.M);
    assert_true(out[0][k].cost == out[1][k].cost);
    assert_int_equal(out[0][k].redrawn, out[1][k].redrawn);
    assert_int_equal(out[0][k].over_limits, out[1][k].over_limits);
    assert_int_equal(out[0][k].rollouts, out[1][k].rollouts);
    assert_true(out[1][k].redrawn > 0 && out[1][k].cost < cfg.limit_penalty);

    nds_rollout_out o;
    mjData *d = mj_makeData(f->plan.m);
    assert_non_null(d);
    nds_rollout_ff(&f->plan, d, &cfg.ctrl, &s, (const double(*)[4])sp0, &out[1][k].keys[0][0],
                   cfg.M, cfg.T, cfg.free_flight, &o);
    mj_deleteData(d);
    assert_int_equal(o.diverged, 0);
    assert_true(o.obj_xy[0] == out[1][k].predicted[0] && o.obj_xy[1] == out[1][k].predicted[1]);
    assert_true(o.obj_yaw == out[1][k].predicted[2]);
    assert_true(nd_task_error(&cfg.w, &g, o.obj_xy, o.obj_yaw) == out[1][k].task_error);
  }
}

/* The best plan's peak setpoint speed over its segments from sp0. */
static double plan_peak_speed(const nds_plan *pl, const double sp0[2][4]) {
  double s[2][4], sp[2][4], peak = 0.0;
  memcpy(s, sp0, sizeof(s));
  nd_snap_seg seg;
  for (int i = 0; i < pl->M; i++) {
    nd_snap_seg_make(&seg, (const double(*)[4])s, pl->keys[i], pl->keys[i] + 2, pl->T);
    for (int j = 0; j <= 200; j++) {
      nd_snap_seg_eval(&seg, j * pl->T / 200, sp);
      peak = fmax(peak, hypot(sp[0][ND_V], sp[1][ND_V]));
    }
    nd_snap_seg_eval(&seg, pl->T, s);
  }
  return peak;
}

/* A speed limit set on a running planner (a task's own, nudge-tasks --v-max) plans as a
 * planner created with it: same keypoints from the same seed, within the limit; 0 restores
 * the created limit and sampler; a limit that is not a speed is refused. */
static void test_speed_limit(void **state) {
  fixture *f = *state;
  const nd_goal g = {.x = 0.10, .y = 0.05, .yaw = 0.3};
  nds_state s;
  double sp0[2][4];
  nds_planner_cfg base, slow;
  lab_start(f, &s, sp0, &base);           /* its state and setpoint; the ideal's limits: */
  base = *nds_planner_config(f->planner);
  base.pop = 24, base.iters = 2;
  nds_planner_cfg_fit_limits(&base);
  slow = base;
  slow.v_max = 0.2;
  nds_planner_cfg_fit_limits(&slow);
  char err[256];
  nds_planner *a = nds_planner_create(&f->plan, &base, f->pool, err, sizeof(err));
  nds_planner *b = nds_planner_create(&f->plan, &slow, f->pool, err, sizeof(err));
  assert_non_null(a);
  assert_non_null(b);
  nds_plan pa, pb, fast;
  assert_int_equal(nds_planner_plan(a, &s, (const double(*)[4])sp0, &g, &fast, err, sizeof(err)), 0);
  assert_int_equal(nds_planner_set_v_max(a, 0.2, err, sizeof(err)), 0);
  assert_true(nds_planner_config(a)->v_max == 0.2);
  assert_true(nds_planner_config(a)->key_v_max == slow.key_v_max);
  assert_true(nds_planner_config(a)->std_init[2] == slow.std_init[2]);
  nds_planner_free(a);
  /* Fresh, so both draw from the same seed: set the limit before the first plan. */
  a = nds_planner_create(&f->plan, &base, f->pool, err, sizeof(err));
  assert_non_null(a);
  assert_int_equal(nds_planner_set_v_max(a, 0.2, err, sizeof(err)), 0);
  assert_int_equal(nds_planner_plan(a, &s, (const double(*)[4])sp0, &g, &pa, err, sizeof(err)), 0);
  assert_int_equal(nds_planner_plan(b, &s, (const double(*)[4])sp0, &g, &pb, err, sizeof(err)), 0);
  assert_memory_equal(pa.keys, pb.keys, sizeof(double) * 4 * base.M);
  assert_true(pa.cost == pb.cost && pa.cost < base.limit_penalty);
  const double vf = plan_peak_speed(&fast, (const double(*)[4])sp0),
               vs = plan_peak_speed(&pa, (const double(*)[4])sp0);
  printf("peak setpoint speed: %.3f m/s at the created limit %.2f, %.3f m/s at 0.2\n", vf,
         base.v_max, vs);
  assert_true(vs <= 0.2 * (1.0 + 1e-9));
  assert_true(vf > 0.2);  /* the goal asks for more than 0.2 when the planner may */
  assert_int_equal(nds_planner_set_v_max(a, 0.0, err, sizeof(err)), 0);
  assert_true(nds_planner_config(a)->v_max == base.v_max);
  assert_true(nds_planner_config(a)->key_v_max == base.key_v_max);
  assert_int_equal(nds_planner_set_v_max(a, 5.0 * base.v_max, err, sizeof(err)), 0);
  assert_true(nds_planner_config(a)->v_max == base.v_max);
  assert_int_equal(nds_planner_set_v_max(a, -0.1, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "-0.1"));
  assert_int_equal(nds_planner_set_v_max(a, NAN, err, sizeof(err)), -1);
  assert_true(nds_planner_config(a)->v_max == base.v_max);
  nds_planner_free(a);
  nds_planner_free(b);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_reaches_goals),
      cmocka_unit_test(test_deterministic),
      cmocka_unit_test(test_redraws),
      cmocka_unit_test(test_plan_pool_and_prediction),
      cmocka_unit_test(test_speed_limit),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
