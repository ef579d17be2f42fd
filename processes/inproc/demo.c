/* nudge-demo: the paper's simulation protocol in one process. A 1 ms MuJoCo world with
 * the ground-truth theta, the planner re-planning at 20 Hz of simulated time while the
 * world is paused, the executor following the first keypoint. Pushes the object to five
 * fixed goal poses and reports each. Same seed, same numbers. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_math.h"
#include "nd_parse.h"
#include "nd_rfile.h"
#include "nds_episode.h"

/* Five goals around the start pose (object at the origin, yaw 0): straight, sideways
 * both ways, with turns, and one behind-the-start push that needs the sphere to go around. */
static const nd_goal goals[5] = {
    {.x = 0.20, .y = 0.00, .yaw = 0.0},
    {.x = 0.15, .y = 0.12, .yaw = 0.6},
    {.x = 0.15, .y = -0.12, .yaw = -0.6},
    {.x = 0.05, .y = 0.20, .yaw = 1.2},
    {.x = -0.10, .y = -0.15, .yaw = -0.5},
};

/* "1e-2" rather than printf's "1e-02": the summary line is read by scripts and people. */
static const char *fmt_eps(double eps, char *buf, int len) {
  double e = log10(eps);
  if (fabs(e - round(e)) < 1e-9) snprintf(buf, len, "1e%d", (int)round(e));
  else snprintf(buf, len, "%g", eps);
  return buf;
}

static void usage(FILE *f) {
  fprintf(f,
          "usage: nudge-demo [options]\n"
          "Push the object to 5 fixed goal poses in MuJoCo, planning with iCEM (in-process,\n"
          "simulated time, deterministic for a seed).\n\n"
          "  --seed N        planner seed (default 1)\n"
          "  --pop N         iCEM population (default 128, the paper's simulation setting)\n"
          "  --iters N       iCEM iterations (default 4)\n"
          "  --threads N     rollout workers, 1..64 (default: online cores)\n"
          "  --plan-dt S     planning model timestep, s (default 0.005; the world uses 0.001)\n"
          "  --tau S         time limit per goal, s (default 5)\n"
          "  --goals N       run only the first N goals, 1..5 (default 5)\n"
          "  -h, --help      this text\n\n"
          "Ends with: reached K/N goals (eps 1e-2), J/N (eps 1e-3)\n");
}

int main(int argc, char **argv) {
  char err[512];
  uint64_t seed = 1;
  int pop = 128, iters = 4, ngoals = 5;
  int threads = (int)sysconf(_SC_NPROCESSORS_ONLN);
  double plan_dt = 0.005, tau = 5.0;
  if (threads < 1) threads = 1;

  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    const int known = !strcmp(a, "--seed") || !strcmp(a, "--pop") || !strcmp(a, "--iters") ||
                      !strcmp(a, "--threads") || !strcmp(a, "--goals") ||
                      !strcmp(a, "--plan-dt") || !strcmp(a, "--tau");
    if (!known || i + 1 >= argc) {
      fprintf(stderr, known ? "nudge-demo: %s needs a value\n" : "nudge-demo: unknown option: %s\n",
              a);
      usage(stderr);
      return 2;
    }
    const char *v = argv[++i];
    int rc;
    if (!strcmp(a, "--seed")) rc = nd_parse_u64(v, "--seed", &seed, err, sizeof(err));
    else if (!strcmp(a, "--pop")) rc = nd_parse_int(v, "--pop", 4, 100000, &pop, err, sizeof(err));
    else if (!strcmp(a, "--iters")) rc = nd_parse_int(v, "--iters", 1, 100, &iters, err, sizeof(err));
    else if (!strcmp(a, "--threads")) rc = nd_parse_int(v, "--threads", 1, 64, &threads, err, sizeof(err));
    else if (!strcmp(a, "--goals")) rc = nd_parse_int(v, "--goals", 1, 5, &ngoals, err, sizeof(err));
    else if (!strcmp(a, "--plan-dt")) rc = nd_parse_double(v, "--plan-dt", 1e-4, 0.02, &plan_dt, err, sizeof(err));
    else if (!strcmp(a, "--tau")) rc = nd_parse_double(v, "--tau", 0.1, 600, &tau, err, sizeof(err));
    else {
      fprintf(stderr, "nudge-demo: unknown option: %s\n", a);
      usage(stderr);
      return 2;
    }
    if (rc) {
      fprintf(stderr, "nudge-demo: %s\n", err);
      return 2;
    }
  }
  /* The one file it may write is MuJoCo's MUJOCO_LOG.TXT (on a warning): not world-writable
   * even under umask 0. */
  nd_rfile_umask_no_world_write();

  nds_scene_cfg wc, pc;
  nds_scene_cfg_default(&wc);
  pc = wc;
  pc.timestep = plan_dt;
  nds_model world = {0}, plan_model = {0};
  nd_pool *pool = NULL;
  nds_planner *planner = NULL;
  mjData *d = NULL;
  int status = 1;
  if (nds_model_init(&world, &wc, err, sizeof(err)) ||
      nds_model_init(&plan_model, &pc, err, sizeof(err)))
    goto done;
  if (!(pool = nd_pool_create(threads, err, sizeof(err)))) goto done;
  nds_planner_cfg cfg;
  nds_planner_cfg_default(&cfg);
  cfg.pop = pop;
  cfg.iters = iters;
  cfg.seed = seed;
  if (!(planner = nds_planner_create(&plan_model, &cfg, pool, err, sizeof(err)))) goto done;
  if (!(d = mj_makeData(world.m))) {
    snprintf(err, sizeof(err), "out of memory for the world's mjData");
    goto done;
  }
  nds_episode_cfg ec;
  nds_episode_cfg_default(&ec);
  ec.tau = tau;

  printf("nudge-demo: world dt %.3f s, plan dt %.3f s, iCEM N %d C %d, %d worker(s), seed %llu\n",
         world.m->opt.timestep, plan_model.m->opt.timestep, pop, iters, threads,
         (unsigned long long)seed);
  int reached = 0, fine = 0;
  const double ee0[2] = {-0.10, 0.0};
  nds_state start;
  nds_state_rest(&world, 0.0, 0.0, 0.0, ee0, &start);
  for (int g = 0; g < ngoals; g++) {
    nds_episode_out o;
    nds_planner_reset(planner);
    if (nds_episode_run(&world, d, planner, &cfg.ctrl, &ec, &start, &goals[g], NULL, NULL, &o,
                        err, sizeof(err)))
      goto done;
    reached += o.reached;
    fine += o.reached_fine;
    printf("goal %d/%d (%+.2f, %+.2f, %+5.1f deg): %-11s t %.2f s  pos err %.4f m  "
           "yaw err %4.1f deg  plans %d  plan %.1f ms\n",
           g + 1, ngoals, goals[g].x, goals[g].y, goals[g].yaw * 180.0 / ND_PI,
           o.reached ? "reached" : "not reached", o.reached ? o.t_reached : o.t_end, o.pos_err,
           o.yaw_err * 180.0 / ND_PI, o.plans, o.plan_ms);
    fflush(stdout);
  }
  char e1[32], e2[32];
  printf("reached %d/%d goals (eps %s), %d/%d (eps %s)\n", reached, ngoals,
         fmt_eps(ec.eps, e1, sizeof(e1)), fine, ngoals, fmt_eps(ec.eps_fine, e2, sizeof(e2)));
  status = 0;
done:
  if (status) fprintf(stderr, "nudge-demo: %s\n", err);
  if (d) mj_deleteData(d);
  nds_planner_free(planner);
  nd_pool_free(pool);
  nds_model_free(&plan_model);
  nds_model_free(&world);
  return status;
}
