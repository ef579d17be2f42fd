/* nudge-planner: the MPC planner process (planner.h says what each file does). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "nd_opt.h"
#include "planner.h"

int main(int argc, char **argv) {
  planner_opts o = {.threads = ndp_default_threads(), .pop = 20, .iters = 2, .seed = 1,
                    .max_rate = 40.0, .state_timeout = 0.1, .lead = 1, .release = 0.01};
  static const char *const lead_words[] = {"off", "on", NULL};
  static const char *const arm_words[] = {"none", "panda", NULL};
  static const char *const prox_words[] = {"straight", "round", NULL};
  int arm = 0;
  /* 10 ms, not the demo's 5 ms: on one core it plans at ~19 Hz while pushing, above the
   * 10 Hz the executor's 0.1 s plan timeout needs; 5 ms did not reach that. Its cost in
   * prediction error is in nudge-bench (doc/decisions.md#plan-dt). */
  o.plan_dt = 0.01;
  memcpy(o.theta, nd_theta_true, sizeof(o.theta));
  nds_planner_cfg pc;
  nds_planner_cfg_default(&pc);
  /* N 20 with draws beyond the limits drawn again simulates about as many candidates as the
   * paper's N 50 without, all of them executable (doc/decisions.md#redraw). */
  pc.redraws = 8;
  /* The task ends when it meets eps: plans are scored by when they get there, not by the
   * horizon's end alone (doc/decisions.md#arrival). A world the model predicts less well
   * wants plans aimed inside eps (nudge-up --world lab: LAB_PLAN_AIM). */
  pc.arrival = 1.0;
  for (int k = 0; k < 2; k++) o.ws.lo[k] = pc.ws_lo[k], o.ws.hi[k] = pc.ws_hi[k];
  nd_opt opts[] = {
      {"lcm-url", ND_OPT_STRING, &o.url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
      {"threads", ND_OPT_INT, &o.threads, 1, 256,
       .def = "one per core",
       .help = "rollout workers, below the 1 kHz processes' real-time threads and (nice +5) "
               "below this process's LCM receive thread"},
      {"pop", ND_OPT_INT, &o.pop, 4, 100000,
       .help = "iCEM population N (the paper's robot setting is 50, drawn without --redraws)"},
      {"iters", ND_OPT_INT, &o.iters, 1, 100, .help = "iCEM iterations C (the paper's robot setting)"},
      {"plan-dt", ND_OPT_DOUBLE, &o.plan_dt, 1e-4, 0.01, .arg = "S",
       .help = "planning model timestep (the tracking controller is stable up to 10 ms); at "
               "10 ms its contact is calibrated to the 1 ms world (nudge-calibrate); see "
               "nudge-bench for its prediction error"},
      {"seed", ND_OPT_U64, &o.seed, .help = "planner seed"},
      {"arrival", ND_OPT_DOUBLE, &pc.arrival, 0.0, 1.0, .arg = "F",
       .help = "score a plan that meets F times the task's eps within the horizon, and stays "
               "within it, by when it gets there (F below 1 leaves room for the model's "
               "error); 0 scores the horizon's end alone (the paper's cost)"},
      {"prox-way", ND_OPT_CHOICE, &pc.prox_round, .choices = prox_words,
       .arg = "straight|round", .def = "straight",
       .help = "how the cost's proximity term measures the sphere's way to where a push "
               "starts: straight, as the paper does, or round the object, 5 mm clear of its "
               "sides and turning only within --workspace, which finds the way round a box "
               "whose near end is beyond reach (nudge-up --world lab sets round)"},
      {"lead", ND_OPT_CHOICE, &o.lead, .choices = lead_words, .arg = "on|off", .def = "on",
       .help = "latency compensation: plan from the state predicted for when the plan will "
               "reach the executor (the executor's committed trajectory from EE_CMD), and "
               "have it start then; off plans from the newest measurement, started on arrival"},
      {"max-rate", ND_OPT_DOUBLE, &o.max_rate, 0.1, 1000, .arg = "HZ",
       .help = "at most this many plans per second"},
      {"state-timeout", ND_OPT_DOUBLE, &o.state_timeout, 1e-3, 10, .arg = "S",
       .help = "plan only from MOCAP and ROBOT_STATE younger than this"},
      {"theta", ND_OPT_THETA, o.theta, .def = "the simulation's ground truth",
       .help = "initial theta: sliding, torsional, rolling friction, sphere mass in kg; used "
               "until PARAMS arrives, plans then carry theta_version -1"},
      {"workspace", ND_OPT_BOX, &o.ws,
       .help = "box in metres the keypoints are drawn in; nudge-executor refuses plans with a "
               "keypoint outside its own --workspace, nudge-bridge commands beyond its own: "
               "give all three the same box (nudge-up --workspace does)"},
      {"v-max", ND_OPT_DOUBLE, &pc.v_max, 1e-3, 10.0, .arg = "M/S",
       .help = "end-effector speed a plan may reach; keep it below nudge-executor's --v-max, "
               "which refuses plans beyond its own (nudge-up --world lab sets both)"},
      {"a-max", ND_OPT_DOUBLE, &pc.a_max, 1e-3, 1000.0, .arg = "M/S2",
       .help = "end-effector acceleration a plan may reach; below nudge-executor's --a-max"},
      {"arm", ND_OPT_CHOICE, &arm, .choices = arm_words, .arg = "none|panda", .def = "none",
       .help = "the robot's arm: panda ranks plans that would bring one of its joints near "
               "a velocity or acceleration limit behind every plan that would not, as the "
               "Cartesian limits do (the lab world's arm; nudge-up --world lab sets it)"},
      {"arm-load", ND_OPT_DOUBLE, &pc.reach_max, 0.1, 1.0, .arg = "R",
       .help = "with --arm: the share of a joint limit a plan may use"},
      {"redraws", ND_OPT_INT, &pc.redraws, 0, 100,
       .help = "draw a candidate beyond the limits (Cartesian or the arm's) again up to this "
               "many times before it is scored: sampling truncated to what the robot can do, "
               "so more of N is simulated where the limits are low"},
      {"release", ND_OPT_DOUBLE, &o.release, 0.0, 0.1, .arg = "M",
       .help = "when a task ends, one last plan brings the sphere to rest this far clear of "
               "the object's sides (where it is, if it already is), and again while idle if the "
               "object comes within 3/4 of that: held pressing on it, the object would creep "
               "on into the next task"},
      {"segment-time", ND_OPT_DOUBLE, &pc.T, 0.05, 2.0, .arg = "S",
       .help = "duration of each keypoint's minimum-snap segment (the horizon is M times it); "
               "slower arms need longer ones to move as far"},
  };
  nd_opt_spec spec = {PROG, "[options]",
                      "MPC planner: plans minimum-snap keypoints with iCEM on MuJoCo rollouts "
                      "from the newest MOCAP / ROBOT_STATE / EE_CMD, toward the active TASK, "
                      "with theta from PARAMS; publishes PLAN back to back (at most --max-rate) "
                      "until the task's EPISODE ends it.",
                      NULL, opts, sizeof(opts) / sizeof(opts[0])};
  int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;

  ndp_signals();
  ndp_mujoco_handlers(PROG);
  char err[512] = "";
  int status = 1;
  nds_model pm = {0};
  nds_reach reach = {0};
  nd_pool *pool = NULL;
  static planner_proc p;
  p.o = &o;
  p.theta_version = -1;
  p.place.place_id = -1;
  ndp_status_init(&p.st, PROG);
  p.st.state = "idle";

  nds_scene_cfg sc;
  const int calibrated = nds_scene_cfg_planning(&sc, o.plan_dt);
  memcpy(sc.theta, o.theta, sizeof(sc.theta));
  pc.pop = o.pop;
  pc.iters = o.iters;
  pc.seed = o.seed;
  nds_planner_cfg_fit_limits(&pc);
  for (int k = 0; k < 2; k++) pc.ws_lo[k] = o.ws.lo[k], pc.ws_hi[k] = o.ws.hi[k];
  if (arm) {
    if (nds_reach_build_ws(&reach, pc.ws_lo, pc.ws_hi, err, sizeof(err))) goto done;
    pc.reach = &reach;
  }
  /* LCM first: its receive thread keeps the process's priority. Then the planning threads
   * (this one and the pool's, which inherit it) step below it, so a plan that runs long on
   * a loaded machine never starves the socket. Linux's nice is per thread. */
  if (!(p.lcm = ndp_lcm_create(o.url, err, sizeof(err))) || planner_subscribe(&p, err, sizeof(err)))
    goto done;
  errno = 0;
  if (setpriority(PRIO_PROCESS, (id_t)syscall(SYS_gettid), getpriority(PRIO_PROCESS, 0) +
                  PLANNER_COMPUTE_NICE) != 0)
    fprintf(stderr, PROG ": cannot lower the planning threads' priority: %s\n", strerror(errno));
  if (nds_model_init(&pm, &sc, err, sizeof(err)) ||
      !(pool = nd_pool_create(o.threads, err, sizeof(err))) ||
      !(p.planner = nds_planner_create(&pm, &pc, pool, err, sizeof(err))))
    goto done;
  /* The object moves only when the sphere (at most v_max) pushes it, and its surface is at
   * least the smaller half side from its centre: faster readings are glitches. */
  nd_objest_cfg ec;
  nd_objest_cfg_default(&ec, pc.v_max, pc.v_max / fmin(pm.cfg.obj_half[0], pm.cfg.obj_half[1]));
  nd_objest_init(&p.est, &ec);
  p.obj_half[0] = pm.cfg.obj_half[0];
  p.obj_half[1] = pm.cfg.obj_half[1];
  p.ee_radius = pm.cfg.ee_radius;

  char theta[200];
  nd_theta_str(o.theta, ", ", theta, sizeof(theta));
  fprintf(stderr,
          PROG ": %s, iCEM N %d C %d, M %d, T %.2f s, plan dt %.4f s (%s contact), %d worker(s), max %.1f "
          "plans/s, lead %s, arrival %g, proximity %s, arm %s (load <= %g), redraws %d, state timeout %.3f s, theta (%s), seed %llu, keypoints in "
          "x [%g, %g] y [%g, %g] m, v_max %g m/s, a_max %g m/s^2\n",
          ndp_url(o.url), o.pop, o.iters, pc.M, pc.T, o.plan_dt,
          calibrated ? "calibrated" : "the world's", o.threads, o.max_rate,
          lead_words[o.lead], pc.arrival, prox_words[pc.prox_round], arm_words[arm], pc.reach_max, pc.redraws, o.state_timeout, theta,
          (unsigned long long)o.seed, pc.ws_lo[0], pc.ws_hi[0], pc.ws_lo[1], pc.ws_hi[1],
          pc.v_max, pc.a_max);

  const double period = 1.0 / o.max_rate;
  double next_plan = 0.0, last = ndp_mono();
  while (!ndp_quit) {
    double now = ndp_mono();
    /* Wait for input, but not past the next allowed plan; 10 ms keeps the heartbeat and
     * the freshness check responsive when nothing arrives. */
    double wait = 0.01;
    if (p.active && planner_state_fresh(&p, now)) wait = fmin(wait, fmax(0.0, next_plan - now));
    if (ndp_handle(p.lcm, wait)) {
      snprintf(err, sizeof(err), "LCM receive failed: %s", strerror(errno));
      goto done;
    }
    if (ndp_quit) break;
    planner_drained(&p);
    now = ndp_mono();
    if (!p.active) {
      p.st.state = "idle";
      if (p.place_due     ? planner_place(&p, now, err, sizeof(err))
          : p.release_due ? planner_release(&p, now, err, sizeof(err))
                          : planner_keep_clear(&p, now, err, sizeof(err)))
        goto done;
    } else if (!planner_state_fresh(&p, now)) {
      p.st.state = "stale";
      p.task_stale += now - last;
    } else {
      p.st.state = "planning";
      if (now >= next_plan) {
        next_plan = now + period;
        if (planner_plan_once(&p, now, err, sizeof(err))) goto done;
      }
    }
    last = now;
    if (ndp_status_tick(p.lcm, &p.st, 0) < 0) {
      snprintf(err, sizeof(err), "publishing on %s failed", NDP_CH_STATUS);
      goto done;
    }
  }
  /* An EPISODE that came during the last plan still tells how the task ended. */
  ndp_drain(p.lcm);
  if (p.active) planner_task_summary(&p, "interrupted");
  p.st.state = "stopped";
  ndp_status_tick(p.lcm, &p.st, 1);
  status = 0;

done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  if (p.lcm) lcm_destroy(p.lcm);
  nds_planner_free(p.planner);
  nd_pool_free(pool);
  nds_model_free(&pm);
  nds_reach_free(&reach);
  return status;
}
