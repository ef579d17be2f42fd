/* nudge-tasks: the episode runner (tasks.h says what each file does). */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "nd_opt.h"
#include "nd_stats.h"
#include "tasks.h"

static tasks_cfg cfg; /* static: the goal list is large */

int main(int argc, char **argv) {
  const int pa = tasks_options(argc, argv, &cfg);
  if (pa != ND_OPT_RUN) return pa;
  ndp_signals();
  /* A file-size limit must fail the append (EFBIG, reported), not kill the runner. */
  signal(SIGXFSZ, SIG_IGN);

  char err[512];
  static tasks_buffer buf;
  static tasks_io io;
  double tau_max = cfg.tau;
  for (int i = 0; i < cfg.n; i++) tau_max = fmax(tau_max, cfg.goals[i].tau);
  if (cfg.record) {
    if (tasks_buffer_open(&buf, cfg.record, tau_max, cfg.record_dt, cfg.record_control,
                          cfg.theta, err, sizeof(err))) {
      fprintf(stderr, PROG ": --record %s\n", err);
      tasks_buffer_close(&buf);
      return 1;
    }
    buf.rec.join = cfg.record_join;
    io.buf = &buf;
  }
  const char *url = ndp_url(cfg.url);
  int status = 1, ran = 0, reached = 0, attempted = 0, stops = 0, met = 0, moved = 0, pushed = 0;
  double t_sum = 0.0, pos_sum = 0.0, task_s = 0.0, obj_path = 0.0, ee_path = 0.0;
  double approach_sum = 0.0, push_sum = 0.0;
  int64_t plans = 0;
  static double reach_t[MAX_GOALS], ages[MAX_PLAN_AGES];
  io.ages = ages;
  ndp_status_init(&io.st, PROG);
  io.st.state = "waiting";
  lcm_t *lcm = ndp_lcm_create(url, err, sizeof(err));
  if (!lcm || tasks_subscribe(&io, lcm, err, sizeof(err))) goto done;
  char vbuf[32] = "the planner's";
  if (cfg.v_max > 0.0) snprintf(vbuf, sizeof(vbuf), "%g m/s", cfg.v_max);
  fprintf(stderr, PROG ": %d goal(s), eps %g, tau %g s, speed limit %s, workspace %.2f m, "
          "settle %g s, lcm %s\n", cfg.n, cfg.eps, cfg.tau, vbuf, cfg.workspace, cfg.settle, url);
  const int w = tasks_wait_mocap(lcm, &io, cfg.wait, err, sizeof(err));
  if (w < 0) goto done;
  if (w == 0 && !ndp_quit) {
    snprintf(err, sizeof(err), "no %s within %g s on %s: is nudge-bridge running on the same "
             "LCM URL?", io.frames ? "ROBOT_STATE" : "MOCAP frame", cfg.wait, url);
    goto done;
  }
  /* Task ids continue from the wall clock in ms, so a restarted runner never reuses an id
   * a planner may still hold. */
  const int64_t id0 = ndp_utime() / 1000;
  for (int i = 0; i < cfg.n && !ndp_quit; i++) {
    tasks_result r;
    if (cfg.place) {
      const int pl = tasks_place(lcm, &io, &cfg, err, sizeof(err));
      if (pl < 0) goto done;
      if (pl == 0 && !ndp_quit) {
        char pk[160] = "";
        if (cfg.park)
          snprintf(pk, sizeof(pk), ", with the sphere parked within %g m of (%g, %g) m "
                   "(nudge-planner's log says why not)", PARK_AT, cfg.park_xy[0],
                   cfg.park_xy[1]);
        snprintf(err, sizeof(err), "--place: the object was not at (%g, %g) m, yaw %g rad%s "
                 "within %g s of asking on %s (nudge-bridge puts it there once the sphere is %g "
                 "m clear and at rest; on a robot, put it there by hand)", cfg.place_pose.x,
                 cfg.place_pose.y, cfg.place_pose.yaw, pk, cfg.place_wait, NDP_CH_PLACE,
                 PLACE_CLEAR);
        goto done;
      }
    } else if (tasks_settle(lcm, &io, &cfg, err, sizeof(err))) {
      goto done;
    }
    if (ndp_quit) break;
    if (tasks_run(lcm, &io, &cfg, &cfg.goals[i], id0 + i, &r, err, sizeof(err))) goto done;
    tasks_print(i, cfg.n, &cfg.goals[i], &r);
    if (cfg.record)
      tasks_buffer_finish(&buf, id0 + i, r.interrupted ? ND_OUTCOME_ABORTED
                                         : r.event == NUDGE_EPISODE_T_EVENT_SUCCESS ? ND_OUTCOME_SUCCESS
                                                                                    : ND_OUTCOME_TIMEOUT,
                          r.obj_path);
    if (r.interrupted) break;
    ran++;
    const int rejected = r.event == NUDGE_EPISODE_T_EVENT_REJECTED;
    attempted += !rejected;
    pos_sum += rejected ? 0.0 : r.pos_err;
    if (r.event == NUDGE_EPISODE_T_EVENT_SUCCESS) reach_t[reached++] = r.time, t_sum += r.time;
    if (r.moved_at >= 0.0) moved++, approach_sum += r.moved_at;
    if (r.moved_at >= 0.0 && r.event == NUDGE_EPISODE_T_EVENT_SUCCESS)
      pushed++, push_sum += r.time - r.moved_at;
    stops += r.event == NUDGE_EPISODE_T_EVENT_STOPPED;
    met += r.met_at_start;
    task_s += rejected ? 0.0 : r.time;
    plans += r.plans;
    obj_path += r.obj_path;
    ee_path += r.ee_path;
    if (tasks_pause(lcm, &io, &cfg, err, sizeof(err))) goto done;
  }
  io.st.state = "done";
  ndp_status_tick(lcm, &io.st, 1);

  /* name value unit lines for scripts, then the line people read. */
  printf("tasks_run %d count\ntasks_reached %d count\n", ran, reached);
  if (reached) {
    printf("reach_time_mean %.3f s\n", t_sum / reached);
    printf("reach_time_median %.3f s\n", nd_stats_of(reach_t, reached).median);
  }
  /* Where a task's time goes: until the object first moves (TASKS_MOVED), and from then on
   * to the goal in the tasks that reached it. */
  if (moved) printf("approach_time_mean %.3f s\n", approach_sum / moved);
  if (pushed) printf("push_time_mean %.3f s\n", push_sum / pushed);
  if (attempted) {
    printf("final_pos_err_mean %.4f m\n", pos_sum / attempted);
    printf("object_path_mean %.3f m\nsphere_path_mean %.3f m\n", obj_path / attempted,
           ee_path / attempted);
  }
  printf("reflex_stops %d count\nreflex_stops_between %d count\ntasks_met_at_start %d count\n",
         stops, io.stops_between, met);
  if (task_s > 0) printf("plan_rate_hz %.1f Hz\n", (double)plans / task_s);
  if (io.nages) {
    printf("plan_age_ms_p50 %.1f ms\n", nd_quantile(ages, io.nages, 0.5));
    printf("plan_age_ms_p99 %.1f ms\n", nd_quantile(ages, io.nages, 0.99));
  }
  if (cfg.record)
    printf("tasks_recorded %lld count\ntasks_record_failed %lld count\n",
           (long long)buf.appended, (long long)buf.failed);
  if (ndp_quit)
    printf("reached %d/%d goals (interrupted: %d of %d tasks ran)\n", reached, ran, ran, cfg.n);
  else
    printf("reached %d/%d goals\n", reached, ran);
  fflush(stdout);
  status = ndp_quit ? 128 + ndp_quit : 0;
  if (buf.failed) {
    fprintf(stderr, PROG ": %lld task(s) not recorded: appending to %s failed; the last "
            "error: %s\n", (long long)buf.failed, buf.path, buf.last_err);
    if (status == 0) status = 3;
  }
done:
  if (status == 1 && ndp_quit) status = 128 + ndp_quit;
  else if (status == 1) fprintf(stderr, PROG ": %s\n", err);
  if (lcm) lcm_destroy(lcm);
  if (cfg.record) tasks_buffer_close(&buf);
  return status;
}
