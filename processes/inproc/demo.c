/* nudge-demo: the paper's simulation protocol in one process. A 1 ms MuJoCo world with
 * the ground-truth theta, the planner re-planning at 20 Hz of simulated time while the
 * world is paused, the executor following the first keypoint. Pushes the object to five
 * fixed goal poses and reports each. Same seed, same numbers. */
#include <math.h>
#include <stdio.h>

#include "nd_math.h"
#include "nd_opt.h"
#include "nd_rfile.h"
#include "nds_episode.h"
#include "nds_setup.h"

#define PROG "nudge-demo"

/* "1e-2" rather than printf's "1e-02": the summary line is read by scripts and people. */
static const char *fmt_eps(double eps, char *buf, int len) {
  const double e = log10(eps);
  if (fabs(e - round(e)) < 1e-9) snprintf(buf, len, "1e%d", (int)round(e));
  else snprintf(buf, len, "%g", eps);
  return buf;
}

int main(int argc, char **argv) {
  uint64_t seed = 1;
  int pop = 128, iters = 4, redraws = 0, ngoals = NDS_DEMO_GOALS, threads = nds_setup_cores(64);
  double plan_dt = 0.005, tau = 5.0;
  nd_opt opts[] = {
      {"seed", ND_OPT_U64, &seed, .help = "planner seed"},
      {"pop", ND_OPT_INT, &pop, 4, 100000, .help = "iCEM population (the paper's simulation setting)"},
      {"iters", ND_OPT_INT, &iters, 1, 100, .help = "iCEM iterations"},
      {"redraws", ND_OPT_INT, &redraws, 0, 100,
       .help = "draw a candidate beyond the limits again up to this many times (nudge-planner's "
               "--redraws; the live planner's setting is --pop 20 --iters 2 --redraws 8)"},
      {"threads", ND_OPT_INT, &threads, 1, 64, .help = "rollout workers", .def = "online cores"},
      {"plan-dt", ND_OPT_DOUBLE, &plan_dt, 1e-4, 0.02, .arg = "S",
       .help = "planning model timestep, s (the world steps at 0.001)"},
      {"tau", ND_OPT_DOUBLE, &tau, 0.1, 600, .arg = "S", .help = "time limit per goal, s"},
      {"goals", ND_OPT_INT, &ngoals, 1, NDS_DEMO_GOALS, .help = "run only the first N goals"},
  };
  nd_opt_spec spec = {PROG, "[options]",
                      "Push the object to 5 fixed goal poses in MuJoCo, planning with iCEM "
                      "(in-process, simulated time, deterministic for a seed).",
                      "Ends with: reached K/N goals (eps 1e-2), J/N (eps 1e-3)", opts,
                      sizeof(opts) / sizeof(opts[0])};
  const int rc = nd_opt_parse(&spec, argc, argv);
  if (rc != ND_OPT_RUN) return rc;
  /* The one file it may write is MuJoCo's MUJOCO_LOG.TXT (on a warning): not world-writable
   * even under umask 0. */
  nd_rfile_umask_no_world_write();

  char err[512];
  nds_setup s;
  nds_planner *planner = NULL;
  int status = 1;
  if (nds_setup_init(&s, plan_dt, threads, err, sizeof(err))) goto done;
  nds_planner_cfg cfg;
  nds_planner_cfg_default(&cfg);
  cfg.pop = pop;
  cfg.iters = iters;
  cfg.redraws = redraws;
  cfg.seed = seed;
  if (!(planner = nds_planner_create(&s.plan, &cfg, s.pool, err, sizeof(err)))) goto done;
  nds_episode_cfg ec;
  nds_episode_cfg_default(&ec);
  ec.tau = tau;

  printf(PROG ": world dt %.3f s, plan dt %.3f s, iCEM N %d C %d, redraws %d, %d worker(s), "
         "seed %llu\n", s.world.m->opt.timestep, s.plan.m->opt.timestep, pop, iters, redraws, threads,
         (unsigned long long)seed);
  int reached = 0, fine = 0;
  for (int g = 0; g < ngoals; g++) {
    const nd_goal *goal = &nds_demo_goals[g];
    nds_episode_out o;
    nds_planner_reset(planner);
    if (nds_episode_run(&s.world, s.d, planner, &cfg.ctrl, &ec, &s.start, goal, NULL, NULL,
                        &o, err, sizeof(err)))
      goto done;
    reached += o.reached;
    fine += o.reached_fine;
    printf("goal %d/%d (%+.2f, %+.2f, %+5.1f deg): %-11s t %.2f s  pos err %.4f m  "
           "yaw err %4.1f deg  plans %d  plan %.1f ms\n",
           g + 1, ngoals, goal->x, goal->y, goal->yaw * 180.0 / ND_PI,
           o.reached ? "reached" : "not reached", o.reached ? o.t_reached : o.t_end, o.pos_err,
           o.yaw_err * 180.0 / ND_PI, o.plans, o.plan_ms);
    fflush(stdout);
  }
  char e1[32], e2[32];
  printf("reached %d/%d goals (eps %s), %d/%d (eps %s)\n", reached, ngoals,
         fmt_eps(ec.eps, e1, sizeof(e1)), fine, ngoals, fmt_eps(ec.eps_fine, e2, sizeof(e2)));
  status = 0;
done:
  if (status) fprintf(stderr, PROG ": %s\n", err);
  nds_planner_free(planner);
  nds_setup_free(&s);
  return status;
}
