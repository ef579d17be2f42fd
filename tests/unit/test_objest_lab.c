/* test_objest_lab: the object's velocity estimate (nd_objest) against the emulated truth.
 *
 * The lab world (the Panda, motion capture with 0.1 mm / 2e-3 rad noise, 6 ms latency and
 * dropped frames, the lab's object) pushes the box along a curve; every released frame
 * goes through nd_objest as the planner's MOCAP handler feeds it, and the estimate at that
 * frame is compared with MuJoCo's own object velocity at the frame's capture time (which
 * is the time the planner predicts from: the latency is covered by its prefix). */
#include <string.h>

#include "nd_math.h"
#include "nd_objest.h"
#include "nd_snap.h"
#include "nd_test.h"
#include "nds_world.h"

#define STEPS 2600        /* ms of the push */
#define HIST 4096         /* truth kept per step */

static void test_against_truth(void **state) {
  (void)state;
  nds_world_cfg wc;
  nds_world_cfg_lab(&wc);
  char err[256];
  nds_world *w = nds_world_create(&wc, err, sizeof err);
  if (!w) fail_msg("%s", err);
  const mjModel *m = nds_world_mj_model(w);
  const mjData *d = nds_world_mj_data(w);
  const int jnt = mj_name2id(m, mjOBJ_JOINT, "object");
  assert_true(jnt >= 0);
  const int dof = m->jnt_dofadr[jnt];

  nd_objest e;
  nd_objest_cfg ec;
  nd_objest_cfg_default(&ec, 0.5, 10.0);
  nd_objest_init(&e, &ec);

  /* The sphere from (-0.10, 0) behind the box through (0.05, 0.01) and on to (0.12,
   * 0.06): a push that also turns the box; within the lab's 0.45 m/s and 1.8 m/s^2. */
  static const double keys[3][4] = {{-0.06, 0.0, 0.2, 0.0}, {0.05, 0.012, 0.2, 0.03},
                                    {0.12, 0.06, 0.0, 0.0}};
  const double T = 0.8;
  nd_snap_seg seg[3];
  double s[2][4] = {{-0.10, 0, 0, 0}, {0, 0, 0, 0}};
  for (int i = 0; i < 3; i++) {
    nd_snap_seg_make(&seg[i], (const double(*)[4])s, keys[i], keys[i] + 2, T);
    nd_snap_seg_eval(&seg[i], T, s);
  }
  static double tv[HIST][3];  /* truth per step: vx, vy, yaw rate */
  double se_v = 0, se_w = 0, se_v_lag = 0, peak_v = 0, peak_w = 0;
  int n = 0, frames = 0;
  const double dt = nds_world_config(w)->dt;
  nds_world_out out;
  for (int k = 0; k < STEPS; k++) {
    double sp[2][4];
    const double t = k * dt;
    int i = (int)(t / T);
    if (i > 2) i = 2;
    nd_snap_seg_eval(&seg[i], t - i * T, sp);
    nds_world_step(w, (const double(*)[4])sp, &out);
    assert_false(out.reset);
    assert_false(out.robot.stopped);
    tv[k][0] = d->qvel[dof];
    tv[k][1] = d->qvel[dof + 1];
    tv[k][2] = d->qvel[dof + 5];  /* body frame z: the yaw rate for a flat box */
    for (int f = 0; f < out.nframes; f++) {
      const nds_world_frame *fr = &out.frame[f];
      nd_objest_add(&e, (int64_t)llround(1e6 * fr->capture_t), fr->obj_pos, fr->obj_quat);
      frames++;
      double v[6];
      nd_objest_velocity(&e, v);
      const int kc = (int)llround(fr->capture_t / dt) - 1;  /* the step that ended there */
      const int kl = (int)llround((fr->capture_t - 0.5 * ec.window) / dt) - 1;
      if (kc < 50 || kl < 0) continue;
      const double *tr = tv[kc];
      const double speed = hypot(tr[0], tr[1]);
      if (speed < 0.02) continue;  /* the box moving */
      se_v += (v[0] - tr[0]) * (v[0] - tr[0]) + (v[1] - tr[1]) * (v[1] - tr[1]);
      se_w += (v[5] - tr[2]) * (v[5] - tr[2]);
      se_v_lag += (v[0] - tv[kl][0]) * (v[0] - tv[kl][0]) + (v[1] - tv[kl][1]) * (v[1] - tv[kl][1]);
      peak_v = fmax(peak_v, speed);
      peak_w = fmax(peak_w, fabs(tr[2]));
      n++;
    }
  }
  const double rv = sqrt(se_v / n), rw = sqrt(se_w / n), rl = sqrt(se_v_lag / n);
  printf("objest_lab_frames %d count\nobjest_lab_moving_frames %d count\n", frames, n);
  printf("objest_lab_speed_peak %.3f m/s\nobjest_lab_yaw_rate_peak %.3f rad/s\n", peak_v, peak_w);
  printf("objest_lab_v_err_rms %.4f m/s\nobjest_lab_w_err_rms %.4f rad/s\n", rv, rw);
  printf("objest_lab_v_err_rms_vs_window_centre %.4f m/s\n", rl);
  assert_true(n > 200);              /* the box moved for most of a second */
  assert_true(peak_v > 0.15);
  assert_true(rv < 0.1 * peak_v + 0.01);
  assert_true(rw < 0.15 * peak_w + 0.05);
  nds_world_free(w);
}

int main(void) {
  const struct CMUnitTest tests[] = {cmocka_unit_test(test_against_truth)};
  return cmocka_run_group_tests(tests, NULL, NULL);
}
