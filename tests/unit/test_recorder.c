/* test_recorder: a rollout from sensor streams (core/nd_recorder.c): object frames
 * interpolated to the steps by lines and by a cubic, lost states filled, and the tasks
 * that must not be recorded refused with the reason. */
#include <string.h>

#include "nd_test.h"
#include "nd_math.h"
#include "nd_recorder.h"

#define DT 0.001
#define U0 1795496793000000LL

static nd_recorder rc;
static const double goal[3] = {0.2, 0.0, 0.3};

/* The scripted world: the sphere moves along x at 0.1 m/s, pushing with 2 N; the object
 * slides along x at 0.05 m/s and turns at 0.5 rad/s; with accel, it also accelerates at
 * 2 m/s^2 along x and 4 rad/s^2 in yaw, as a pushed box does. */
static int accel;
static double obj_x(double t) { return 0.05 * t + (accel ? t * t : 0); }
static double obj_yaw(double t) { return 0.5 * t + (accel ? 2 * t * t : 0); }

static void truth(int64_t us, double ee[2], double pose[ND_ROLLOUT_OBJ]) {
  const double t = 1e-6 * (double)(us - U0);
  ee[0] = -0.1 + 0.1 * t;
  ee[1] = 0.01;
  pose[0] = obj_x(t), pose[1] = 0.0, pose[2] = 0.025;
  nd_yaw_quat(obj_yaw(t), pose + 3);
}

static nd_rec_state state_at(int64_t seq) {
  nd_rec_state s = {.seq = seq, .utime = U0 + 1000 * seq};
  double pose[ND_ROLLOUT_OBJ];
  truth(s.utime, s.ee_pos, pose);
  s.ee_vel[0] = 0.1;
  s.force[0] = 2.0 + 1e-3 * (double)seq;
  return s;
}

/* Record steps [1, n] with frames at 240 Hz; skip the states in [lose0, lose1). */
static void stream(int n, int lose0, int lose1, int period_ms) {
  double ee[2], pose[ND_ROLLOUT_OBJ];
  const nd_rec_state s0 = state_at(0);
  truth(s0.utime, ee, pose);
  nd_recorder_begin(&rc, &s0, s0.utime, pose, 42, goal, nd_theta_true, ND_CTRL_FORCE);
  int64_t next_frame = U0;
  for (int k = 1; k <= n; k++) {
    nd_rec_state s = state_at(k);
    s.utime = U0 + 1000LL * period_ms * k;
    while (next_frame <= s.utime) {  /* 240 Hz frames, in time order with the states */
      truth(next_frame, ee, pose);
      nd_recorder_frame(&rc, next_frame, pose);
      next_frame += 4167;
    }
    if (k % 100 == 0) {
      const nd_rec_setpoint sp = {{0.01 * k, 0}, {0.1, 0}, {0, 0}};
      nd_recorder_setpoint(&rc, &sp);
    }
    if (k < lose0 || k >= lose1) nd_recorder_state(&rc, &s);
  }
  truth(next_frame, ee, pose);  /* the frame after the last step: nothing held at the end */
  nd_recorder_frame(&rc, next_frame, pose);
}

static void test_interpolates_and_fills(void **state) {
  (void)state;
  char err[300];
  assert_int_equal(nd_recorder_init(&rc, 2.0, DT, err, sizeof err), 0);
  stream(1500, 700, 710, 1);  /* ten states lost in a row */
  const nd_rollout *r = NULL;
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), 0);
  assert_int_equal(nd_rollout_check(r, err, sizeof err), 0);
  assert_int_equal(r->n, 1500);
  assert_int_equal(rc.filled, 10);
  assert_int_equal(rc.longest_gap, 10);
  assert_int_equal(r->outcome, ND_OUTCOME_SUCCESS);
  assert_int_equal(r->task_id, 42);
  double worst_pos = 0, worst_yaw = 0, worst_u = 0;
  for (int i = 0; i < r->n; i++) {
    double ee[2], pose[ND_ROLLOUT_OBJ];
    truth(U0 + 1000LL * (i + 1), ee, pose);
    const double *o = nd_rollout_obj(r, i);
    worst_pos = fmax(worst_pos, hypot(o[0] - pose[0], o[1] - pose[1]));
    worst_yaw = fmax(worst_yaw, fabs(nd_wrap_angle(nd_quat_yaw(o + 3) - nd_quat_yaw(pose + 3))));
    /* Filled steps lie on the line between their neighbours: exact for this linear force. */
    worst_u = fmax(worst_u, fabs(r->u[2 * i] - (2.0 + 1e-3 * (i + 1))));
    assert_near(r->ee[2 * i], ee[0], 1e-12);
  }
  printf("recorder_obj_err_max %.3g m, yaw %.3g rad, filled force err %.3g N\n", worst_pos,
         worst_yaw, worst_u);
  assert_true(worst_pos < 1e-12);  /* linear motion interpolates exactly */
  assert_true(worst_yaw < 1e-6);   /* nlerp over 4 ms of a 0.5 rad/s turn */
  assert_true(worst_u < 1e-9);
  /* The newest setpoint before each state; the start position before the first. */
  assert_near(r->sp[6 * 0], r->ee_pos[0], 0);
  assert_near(r->sp[6 * 99], 1.0, 0);     /* step 100: the setpoint posted at k = 100 */
  assert_near(r->sp[6 * 1499], 15.0, 0);
  nd_recorder_free(&rc);
}

/* An accelerating object recorded with frames joined by join: the worst errors of the
 * steps' poses and of their rates over one step (what the replay's anchors take), away
 * from the first and last frame, whose rate is one secant. */
static void curve_errors(int join, double *pos, double *yaw, double *v, double *w) {
  char err[300];
  accel = 1;
  assert_int_equal(nd_recorder_init(&rc, 1.0, DT, err, sizeof err), 0);
  rc.join = join;
  stream(600, 0, 0, 1);
  const nd_rollout *r = NULL;
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), 0);
  *pos = *yaw = *v = *w = 0;
  for (int i = 10; i < r->n - 10; i++) {
    const double *o = nd_rollout_obj(r, i), *p = nd_rollout_obj(r, i - 1);
    const double t = DT * (i + 1), tm = t - 0.5 * DT;
    *pos = fmax(*pos, fabs(o[0] - obj_x(t)));
    *yaw = fmax(*yaw, fabs(nd_wrap_angle(nd_quat_yaw(o + 3) - obj_yaw(t))));
    /* A difference over one step is the rate at its midpoint, for a quadratic exactly. */
    *v = fmax(*v, fabs((o[0] - p[0]) / DT - (0.05 + 2 * tm)));
    const double wi = nd_wrap_angle(nd_quat_yaw(o + 3) - nd_quat_yaw(p + 3)) / DT;
    *w = fmax(*w, fabs(wi - (0.5 + 4 * tm)));
  }
  accel = 0;
  nd_recorder_free(&rc);
}

/* The cubic follows an accelerating object between frames; a line gives each frame
 * interval one rate, off by up to a h / 2 (4.2 mm/s and 8.3 mrad/s here). */
static void test_interpolates_curves(void **state) {
  (void)state;
  double pos, yaw, v, w, lpos, lyaw, lv, lw;
  curve_errors(ND_REC_JOIN_CUBIC, &pos, &yaw, &v, &w);
  curve_errors(ND_REC_JOIN_LINE, &lpos, &lyaw, &lv, &lw);
  printf("recorder_cubic_err_max %.3g m, yaw %.3g rad; rate %.3g m/s, yaw rate %.3g rad/s\n",
         pos, yaw, v, w);
  printf("recorder_line_err_max %.3g m, yaw %.3g rad; rate %.3g m/s, yaw rate %.3g rad/s\n",
         lpos, lyaw, lv, lw);
  assert_true(pos < 1e-12);  /* a quadratic is interpolated exactly */
  assert_true(v < 1e-8);
  assert_true(yaw < 1e-7);   /* yaw lies on the quaternion's circle: not quadratic */
  assert_true(w < 1e-4);
  assert_true(lv > 3e-3 && lv < 5e-3);  /* a h / 2 = 2 m/s^2 x 4.17 ms / 2 */
  assert_true(lw > 6e-3 && lw < 1e-2);
}

/* Velocity records keep the end-effector velocity as the control. */
static void test_velocity_control(void **state) {
  (void)state;
  char err[300];
  assert_int_equal(nd_recorder_init(&rc, 1.0, DT, err, sizeof err), 0);
  double ee[2], pose[ND_ROLLOUT_OBJ];
  const nd_rec_state s0 = state_at(0);
  truth(s0.utime, ee, pose);
  nd_recorder_begin(&rc, &s0, s0.utime, pose, 1, goal, nd_theta_true, ND_CTRL_VELOCITY);
  for (int k = 1; k <= 200; k++) {
    const nd_rec_state s = state_at(k);
    nd_recorder_state(&rc, &s);
  }
  const nd_rollout *r;
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_TIMEOUT, &r, err, sizeof err), 0);
  assert_int_equal(r->control, ND_CTRL_VELOCITY);
  assert_near(r->u[2 * 150], 0.1, 0);
  nd_recorder_free(&rc);
}

/* The tasks that must not become records, each with the reason. */
static void test_refusals(void **state) {
  (void)state;
  char err[300];
  const nd_rollout *r;
  assert_int_equal(nd_recorder_init(&rc, 2.0, DT, err, sizeof err), 0);
  stream(500, 200, 230, 1);  /* 30 lost in a row: more than a gap may be filled */
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "30 robot states lost in a row after seq 199"));
  stream(500, 100, 115, 1);  /* 15 of 500 filled: over 2 % */
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "15 of 500 steps lost"));
  stream(500, 0, 0, 2);      /* a robot stepping every 2 ms, recorded as 1 ms */
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "every 2.000 ms"));
  stream(100, 0, 0, 1);
  const nd_rec_state back = state_at(50);
  nd_recorder_state(&rc, &back);
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "seq went back from 100 to 50"));
  double pose[ND_ROLLOUT_OBJ] = {0, 0, 0.025, 1, 0, 0, 0};
  nd_recorder_begin(&rc, NULL, U0, pose, 7, goal, nd_theta_true, ND_CTRL_FORCE);
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "no robot state received before the task"));
  const nd_rec_state s0 = state_at(0);
  nd_recorder_begin(&rc, &s0, U0, pose, 8, goal, nd_theta_true, ND_CTRL_FORCE);
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "no robot state arrived during the task"));
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_SUCCESS, &r, err, sizeof err), -1);
  assert_non_null(strstr(err, "no task was being recorded"));
  nd_recorder_free(&rc);
}

/* A task longer than the arrays hold is cut off at the capacity, and says so. */
static void test_capacity(void **state) {
  (void)state;
  char err[300];
  assert_int_equal(nd_recorder_init(&rc, 0.1, DT, err, sizeof err), 0);
  const int cap = rc.cap;
  stream(cap + 50, 0, 0, 1);
  assert_int_equal(rc.dropped, 50);
  const nd_rollout *r;
  assert_int_equal(nd_recorder_finish(&rc, ND_OUTCOME_TIMEOUT, &r, err, sizeof err), 0);
  assert_int_equal(r->n, cap);
  assert_int_equal(nd_rollout_check(r, err, sizeof err), 0);
  nd_recorder_free(&rc);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_interpolates_and_fills),
      cmocka_unit_test(test_interpolates_curves),
      cmocka_unit_test(test_velocity_control),
      cmocka_unit_test(test_refusals),
      cmocka_unit_test(test_capacity),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
