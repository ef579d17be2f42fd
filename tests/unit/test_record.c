/* test_record: recording a planned episode (nds_record as the episode hook) and replaying
 * the recording: exact in FORCE and SETPOINT mode under the recording theta, sensitive to
 * theta otherwise; the recorder's bounds and misuse. */
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"
#include "nd_test.h"
#include "nds_episode.h"
#include "nds_tfx.h"
#include "nds_record.h"
#include "nds_replay.h"

typedef struct {
  nds_tfx x;
  nds_state start;
} fixture;

static int setup(void **state) {
  fixture *f = calloc(1, sizeof(*f));
  assert_non_null(f);
  nds_tfx_init(&f->x, 5);
  const double ee0[2] = {-0.10, 0.0};
  nds_state_rest(&f->x.world, 0.0, 0.0, 0.0, ee0, &f->start);
  *state = f;
  return 0;
}

static int teardown(void **state) {
  fixture *f = *state;
  nds_tfx_free(&f->x);
  free(f);
  return 0;
}

static void episode(fixture *f, double tau, const nd_goal *g, nds_record *rec,
                    nds_episode_out *o) {
  char err[256];
  nds_episode_cfg ec;
  nds_episode_cfg_default(&ec);
  ec.tau = tau;
  nds_planner_reset(f->x.planner);
  const nds_planner_cfg *pc = nds_planner_config(f->x.planner);
  if (nds_episode_run(&f->x.world, f->x.d, f->x.planner, &pc->ctrl, &ec, &f->start, g,
                      nds_record_hook, rec, o, err, sizeof(err)))
    fail_msg("episode: %s", err);
}

/* A 1.5 s push with a turn, recorded: one step per world step, the metadata as given, the
 * first setpoint at the sphere. Replayed in the world model under the recording theta,
 * forces and setpoints both give the observations bit for bit (L exactly 0); a lower
 * sliding friction does not. The encoding round-trips the setpoints. */
static void test_record_replays_exactly(void **state) {
  fixture *f = *state;
  char err[256];
  const nd_goal g = {.x = 0.15, .y = 0.12, .yaw = 0.6};
  nds_record rec;
  assert_int_equal(nds_record_init(&rec, 1.5, 0.001, err, sizeof(err)), 0);
  assert_true(rec.cap >= 1501 && rec.cap <= 1502);  /* k dt <= tau: k = 0..1500, + rounding */
  const double theta[ND_NTHETA] = {0.8, 0.004, 2e-4, 1.0, 1, 0, 0};
  assert_int_equal(nds_record_begin(&rec, &f->x.world, &f->start, 42, 1700000000000000LL, &g,
                                    theta, err, sizeof(err)), 0);
  nds_episode_out o;
  episode(f, 1.5, &g, &rec, &o);
  assert_int_equal(nds_record_finish(&rec, o.reached ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT,
                                     err, sizeof(err)), 0);
  const nd_rollout *r = &rec.r;
  const double *last = nd_rollout_obj(r, r->n - 1);
  printf("recorded %d steps (t_end %.3f s), object moved to (%.3f, %.3f, %.3f)\n", r->n,
         o.t_end, last[0], last[1], nd_quat_yaw(last + 3));
  assert_int_equal(r->n, (int)lround(o.t_end / 0.001));
  assert_int_equal(r->task_id, 42);
  assert_true(r->goal[0] == g.x && r->goal[1] == g.y && r->goal[2] == g.yaw);
  assert_memory_equal(r->theta, theta, sizeof(r->theta));  /* the paper's four */
  assert_int_equal(r->control, ND_CTRL_FORCE);
  assert_int_equal(r->outcome, o.reached ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT);
  assert_true(r->dt == 0.001);
  assert_true(r->ee_pos[0] == -0.10 && r->sp[0] == -0.10 && r->sp[1] == 0.0);
  assert_true(hypot(last[0], last[1]) > 0.03);     /* pushed */
  assert_true(fabs(nd_quat_yaw(last + 3)) > 0.05); /* turned */
  for (int k = 0; k < r->n; k++) {
    const double *q = nd_rollout_obj(r, k) + 3; /* the full pose, a unit quaternion */
    assert_near(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1, 1e-12);
  }

  nds_model nm;
  assert_int_equal(nds_model_copy(&nm, &f->x.world, err, sizeof(err)), 0);
  mjData *d = mj_makeData(nm.m);
  double *pred = malloc(sizeof(double) * NDS_REPLAY_PRED_COLS * r->n);
  const int modes[2] = {NDS_REPLAY_FORCE, NDS_REPLAY_SETPOINT};
  for (int i = 0; i < 2; i++) {
    nds_replay_cfg rc;
    nds_replay_cfg_default(&rc, modes[i]);
    nds_replay_terms t;
    assert_int_equal(nds_replay(&nm, d, &rc, r, &t, pred, err, sizeof(err)), 0);
    assert_int_equal(t.steps, r->n);
    assert_true(t.pos_o == 0 && t.pos_ee == 0 && t.rot_o == 0 && !t.diverged);
    for (int k = 0; k < r->n; k++) {
      const double *o = nd_rollout_obj(r, k), yaw = nd_quat_yaw(o + 3);
      assert_memory_equal(pred + 5 * k, o, 2 * sizeof(double));
      assert_memory_equal(pred + 5 * k + 2, &yaw, sizeof(double));
      assert_memory_equal(pred + 5 * k + 3, r->ee + 2 * k, 2 * sizeof(double));
    }
  }
  const double other[ND_NTHETA] = {0.7, 0.005, 1e-4, 1.0, 1, 0, 0};
  assert_int_equal(nds_theta_apply(&nm, other, err, sizeof(err)), 0);
  for (int i = 0; i < 2; i++) {
    nds_replay_cfg rc;
    nds_replay_cfg_default(&rc, modes[i]);
    nds_replay_terms t;
    assert_int_equal(nds_replay(&nm, d, &rc, r, &t, NULL, err, sizeof(err)), 0);
    printf("slide 0.7, %s replay: pos_o %.3e, pos_ee %.3e, rot_o %.3e\n",
           nds_replay_mode_name(modes[i]), t.pos_o, t.pos_ee, t.rot_o);
    assert_true(t.pos_o > 1e-7);
  }

  size_t len = nd_rollout_encoded_size(r->n), got;
  unsigned char *buf = malloc(len);
  assert_int_equal(nd_rollout_encode(r, buf, len, &got, err, sizeof(err)), 0);
  nd_rollout back;
  assert_int_equal(nd_rollout_decode(&back, buf, got, err, sizeof(err)), 0);
  assert_memory_equal(back.sp, r->sp, sizeof(double) * 6 * r->n);
  nd_rollout_free(&back);
  free(buf);
  free(pred);
  mj_deleteData(d);
  nds_model_free(&nm);
  nds_record_free(&rec);
  assert_null(rec.r.u);
}

/* An episode longer than the recorder's capacity fails at finish, saying how long it ran;
 * a recorder sized for another timestep, a finish without begin and bad sizes are refused.
 * The next begin starts a clean recording. */
static void test_record_bounds(void **state) {
  fixture *f = *state;
  char err[256];
  const nd_goal g = {.x = 0.20, .y = 0.0, .yaw = 0.0};
  const double theta[ND_NTHETA] = {1, 0.005, 1e-4, 1, 1, 0, 0};
  nds_record rec;
  assert_int_equal(nds_record_init(&rec, 0.1, 0.001, err, sizeof(err)), 0);
  assert_int_equal(nds_record_finish(&rec, ND_OUTCOME_SUCCESS, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "without begin"));
  assert_int_equal(nds_record_begin(&rec, &f->x.plan, &f->start, 1, 0, &g, theta, err,
                                    sizeof(err)), -1);
  assert_non_null(strstr(err, "timestep"));
  assert_int_equal(nds_record_begin(&rec, &f->x.world, &f->start, 1, 0, &g, theta, err,
                                    sizeof(err)), 0);
  nds_episode_out o;
  episode(f, 0.3, &g, &rec, &o);
  assert_int_equal(nds_record_finish(&rec, ND_OUTCOME_TIMEOUT, err, sizeof(err)), -1);
  printf("%s\n", err);
  char want[96];
  snprintf(want, sizeof(want), "ran %d steps, the recorder holds %d",
           (int)lround(o.t_end / 0.001), rec.cap);
  assert_non_null(strstr(err, want));
  assert_true(rec.cap < 105 && o.t_end > 0.29);
  /* Begin again: no step recorded yet, so finishing now is refused as empty. */
  assert_int_equal(nds_record_begin(&rec, &f->x.world, &f->start, 2, 0, &g, theta, err,
                                    sizeof(err)), 0);
  assert_int_equal(rec.r.n, 0);
  assert_int_equal(nds_record_finish(&rec, ND_OUTCOME_TIMEOUT, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "n = 0"));
  nds_record_free(&rec);
  nds_record_free(&rec);  /* twice is safe */
  assert_int_equal(nds_record_init(&rec, 0, 0.001, err, sizeof(err)), -1);
  assert_int_equal(nds_record_init(&rec, 1e6, 0.001, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "limit"));
  assert_int_equal(nds_record_begin(&rec, &f->x.world, &f->start, 1, 0, &g, theta, err,
                                    sizeof(err)), -1);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_record_replays_exactly),
      cmocka_unit_test(test_record_bounds),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
