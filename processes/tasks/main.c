/* nudge-tasks: the episode runner (tasks.h says what each file does). */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "nd_opt.h"
#include "tasks.h"

/* Start: object at rest at the origin, the bridge's sphere at (-0.10, 0). Each goal is a
 * 14-16 cm push from the previous one, so every task starts with the object near the last
 * goal and a push of about one object length ahead: straight ahead, a diagonal push with a
 * quarter turn, a push sideways onto the long face, a pull back that needs the sphere to go
 * around the object, and a diagonal push back with a turn the other way. All stay well
 * inside the default 0.5 m workspace, so the sphere has room behind the object. */
static const nd_goal chain[] = {
    {.x = 0.15, .y = 0.00, .yaw = 0.0}, {.x = 0.25, .y = 0.10, .yaw = 0.4},
    {.x = 0.25, .y = 0.25, .yaw = 0.8}, {.x = 0.10, .y = 0.30, .yaw = 0.8},
    {.x = 0.00, .y = 0.20, .yaw = 0.3},
};

static int add_goal(const char *v, const char *what, void *dst, char *err, int errlen) {
  tasks_cfg *c = dst;
  char why[400];
  if (c->n >= MAX_GOALS) {
    snprintf(err, errlen, "%s: more than %d goals", what, MAX_GOALS);
    return -1;
  }
  if (nd_goal_parse_arg(v, &c->goals[c->n], why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  c->n++;
  return 0;
}

static int add_goals(const char *v, const char *what, void *dst, char *err, int errlen) {
  tasks_cfg *c = dst;
  const int n0 = c->n;
  char why[400];
  if (nd_goal_list_load(v, c->goals, MAX_GOALS, &c->n, why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  if (c->n == n0) {
    snprintf(err, errlen, "%s: %s: no goals in the file", what, v);
    return -1;
  }
  return 0;
}

static tasks_cfg cfg; /* static: the goal list is large */

int main(int argc, char **argv) {
  cfg = (tasks_cfg){.eps = 1e-2, .tau = 5.0, .workspace = 0.5, .wait = 10.0, .settle = 0.5,
                    .record_dt = 0.001};
  memcpy(cfg.theta, nd_theta_true, sizeof(cfg.theta));
  nd_opt opts[] = {
      {"goal", ND_OPT_CUSTOM, &cfg, .parse = add_goal, .arg = "X,Y,YAW[,EPS[,TIME_LIMIT]]",
       .def = "", .help = "a goal pose (m, m, rad); repeatable, run in order"},
      {"goals", ND_OPT_CUSTOM, &cfg, .parse = add_goals, .arg = "FILE", .def = "",
       .help = "goals from FILE, one per line: x y yaw [eps [time_limit]] ('#' comments, blank "
               "lines ignored); repeatable. Without goals: a chain of 5 pushes of 14-16 cm from "
               "the origin"},
      {"eps", ND_OPT_DOUBLE, &cfg.eps, 1e-12, 1.0, .arg = "E",
       .help = "success threshold on L_pos + 0.02 L_rot (per-goal values override)"},
      {"tau", ND_OPT_DOUBLE, &cfg.tau, 1e-3, ND_GOAL_MAX_TAU, .arg = "S",
       .help = "time limit per task, s (per-goal values override)"},
      {"workspace", ND_OPT_DOUBLE, &cfg.workspace, 1e-3, ND_GOAL_MAX_POS, .arg = "M",
       .help = "goals beyond |x| or |y| > M are rejected"},
      {"wait", ND_OPT_DOUBLE, &cfg.wait, 0.0, 3600.0, .arg = "S",
       .help = "wait for the first MOCAP frame (with --record: and ROBOT_STATE)"},
      {"settle", ND_OPT_DOUBLE, &cfg.settle, 0.0, 3600.0, .arg = "S",
       .help = "pause between tasks so the object comes to rest"},
      {"record", ND_OPT_STRING, &cfg.record, .arg = "FILE",
       .help = "append each task's rollout (start state, 1 kHz forces, setpoints, observed "
               "path) to the replay buffer FILE, created if missing, for nudge-adapter; one "
               "writer at a time"},
      {"record-dt", ND_OPT_DOUBLE, &cfg.record_dt, 1e-5, 0.05, .arg = "S",
       .help = "the robot's control step, s (the bridge's 1/--rate); a task whose ROBOT_STATE "
               "period differs is not recorded"},
      {"theta", ND_OPT_THETA, cfg.theta, .def = "the simulation's ground truth, as the planner",
       .help = "theta recorded as the planner's until PARAMS arrives"},
      {"await-fit", ND_OPT_DOUBLE, &cfg.await_fit, 0.0, 3600.0, .arg = "S",
       .help = "with --record: after appending a task, wait up to S s for PARAMS fitted on it "
               "before the next task (the paper's protocol: refit between episodes); 0: no wait"},
      {"lcm-url", ND_OPT_STRING, &cfg.url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
  };
  nd_opt_spec spec = {
      PROG, "[options]",
      "Run pushing tasks one after another: publish each goal on TASK, follow the object on "
      "MOCAP until the task error L_pos + l1 L_rot falls below eps (reached) or the time limit "
      "passes (timed out), report it on EPISODE and as a line on stdout. The object is not "
      "reset between tasks: each starts where the last one ended.",
      "Prints one line per task, summary figures as 'name value unit' lines, and ends with\n"
      "'reached K/N goals'. Exit status: 0 every task ran (reached, timed out or rejected),\n"
      "1 the tasks could not be run (no MOCAP, LCM failure), 2 bad arguments, 3 every\n"
      "task ran but appending some to the --record buffer failed (disk full, read-only,\n"
      "I/O error: the tasks go on, each failure is reported, earlier records stay intact),\n"
      "128+n when stopped by signal n (SIGINT: 130), after printing what ran.\n",
      opts, sizeof(opts) / sizeof(opts[0])};
  const int pa = nd_opt_parse(&spec, argc, argv);
  if (pa != ND_OPT_RUN) return pa;
  if (cfg.await_fit > 0 && !cfg.record)
    return nd_opt_fail(&spec, "--await-fit needs --record (it waits for the fit of a record)");
  if (cfg.n == 0) {
    cfg.n = (int)(sizeof(chain) / sizeof(chain[0]));
    memcpy(cfg.goals, chain, sizeof(chain));
  }
  ndp_signals();
  /* A file-size limit must fail the append (EFBIG, reported), not kill the runner. */
  signal(SIGXFSZ, SIG_IGN);

  char err[512];
  static tasks_buffer buf;
  static tasks_io io;
  double tau_max = cfg.tau;
  for (int i = 0; i < cfg.n; i++) tau_max = fmax(tau_max, cfg.goals[i].tau);
  if (cfg.record) {
    if (tasks_buffer_open(&buf, cfg.record, tau_max, cfg.record_dt, cfg.theta, err, sizeof(err))) {
      fprintf(stderr, PROG ": --record %s\n", err);
      tasks_buffer_close(&buf);
      return 1;
    }
    io.buf = &buf;
  }
  const char *url = ndp_url(cfg.url);
  int status = 1, ran = 0, reached = 0, attempted = 0;
  double t_sum = 0.0, pos_sum = 0.0;
  ndp_status_init(&io.st, PROG);
  io.st.state = "waiting";
  lcm_t *lcm = ndp_lcm_create(url, err, sizeof(err));
  if (!lcm || tasks_subscribe(&io, lcm, err, sizeof(err))) goto done;
  fprintf(stderr, PROG ": %d goal(s), eps %g, tau %g s, workspace %.2f m, settle %g s, lcm %s\n",
          cfg.n, cfg.eps, cfg.tau, cfg.workspace, cfg.settle, url);
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
    if (tasks_run(lcm, &io, &cfg, &cfg.goals[i], id0 + i, &r, err, sizeof(err))) goto done;
    tasks_print(i, cfg.n, &cfg.goals[i], &r);
    if (cfg.record)
      tasks_buffer_finish(&buf, id0 + i, r.interrupted ? ND_OUTCOME_ABORTED
                                         : r.event == NUDGE_EPISODE_T_EVENT_SUCCESS ? ND_OUTCOME_SUCCESS
                                                                                    : ND_OUTCOME_TIMEOUT);
    if (r.interrupted) break;
    ran++;
    const int rejected = r.event == NUDGE_EPISODE_T_EVENT_REJECTED;
    attempted += !rejected;
    pos_sum += rejected ? 0.0 : r.pos_err;
    if (r.event == NUDGE_EPISODE_T_EVENT_SUCCESS) reached++, t_sum += r.time;
    if (i + 1 < cfg.n && tasks_pause(lcm, &io, &cfg, rejected, err, sizeof(err))) goto done;
  }
  io.st.state = "done";
  ndp_status_tick(lcm, &io.st, 1);

  /* name value unit lines for scripts, then the line people read. */
  printf("tasks_run %d count\ntasks_reached %d count\n", ran, reached);
  if (reached) printf("reach_time_mean %.3f s\n", t_sum / reached);
  if (attempted) printf("final_pos_err_mean %.4f m\n", pos_sum / attempted);
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
