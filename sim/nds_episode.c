/* nds_episode: one task in the paper's simulation protocol (world paused while planning). */
#include "nds_episode.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "nd_math.h"

void nds_episode_cfg_default(nds_episode_cfg *cfg) {
  cfg->eps = 1e-2;
  cfg->eps_fine = 1e-3;
  cfg->tau = 5.0;
  cfg->plan_period = 0.05;
  cfg->exec = nd_exec_cfg_default();
}

static double wall_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* Yaw error modulo the cuboid's half-turn symmetry, in [0, pi/2]. */
static double yaw_error(double yaw, double goal_yaw) {
  double e = fabs(nd_wrap_angle(yaw - goal_yaw));
  return e > 0.5 * ND_PI ? ND_PI - e : e;
}

int nds_episode_run(const nds_model *world, mjData *d, nds_planner *planner,
                    const nds_ctrl_cfg *ctrl, const nds_episode_cfg *cfg,
                    const nds_state *start, const nd_goal *goal, nds_episode_hook hook,
                    void *hook_ctx, nds_episode_out *out, char *err, int errlen) {
  if (nd_exec_cfg_check(&cfg->exec, err, errlen)) return -1;
  if (!(cfg->plan_period > 0.0) || !(cfg->tau > 0.0) || !(cfg->eps > 0.0) ||
      !(cfg->eps_fine > 0.0)) {
    snprintf(err, errlen, "episode: plan_period (%g), tau (%g), eps (%g) and eps_fine (%g) "
             "must be positive", cfg->plan_period, cfg->tau, cfg->eps, cfg->eps_fine);
    return -1;
  }
  if (nds_state_set(world, d, start, err, errlen)) return -1;
  memset(out, 0, sizeof(*out));
  out->t_reached = out->t_fine = cfg->tau;

  const nd_cost_weights *w = &nds_planner_config(planner)->w;
  const double dt = world->m->opt.timestep;
  const double eps_stop = fmin(cfg->eps, cfg->eps_fine);
  nd_exec ex;
  nd_exec_init(&ex, start->ee_pos, 0.0);
  nds_ctrl pid;
  nds_ctrl_reset(&pid, world->m->body_mass[world->ee_body]);
  double next_plan = 0.0, plan_wall = 0.0;
  nds_state s;
  nds_plan plan;
  double sp[2][4], force[2];

  for (long k = 0;; k++) {
    /* Simulated time from the step count: d->time accumulates rounding. */
    const double t = k * dt;
    nds_state_get(world, d, &s);
    const double yaw = nds_state_yaw(&s);
    const double e = nd_task_error(w, goal, s.obj_pos, yaw);
    if (!out->reached && e < cfg->eps) out->reached = 1, out->t_reached = t;
    if (!out->reached_fine && e < cfg->eps_fine) out->reached_fine = 1, out->t_fine = t;
    out->t_end = t;
    out->task_error = e;
    out->pos_err = hypot(s.obj_pos[0] - goal->x, s.obj_pos[1] - goal->y);
    out->yaw_err = yaw_error(yaw, goal->yaw);
    if (e < eps_stop || t > cfg->tau) break;
    if (!nd_all_finite(s.obj_pos, 3)) {
      snprintf(err, errlen, "episode: the world diverged at t = %.3f s", t);
      return -1;
    }

    if (t >= next_plan - 0.5 * dt) {
      /* The world is paused here: the planner sees exactly the state it plans from, and
       * the executor switches at the same instant (the paper's protocol). */
      nd_exec_eval(&ex, t, sp);
      /* The last plan started plan_period ago: go on along it (nds_planner_retime). */
      if (out->plans > 0) nds_planner_retime(planner, cfg->plan_period);
      double w0 = wall_s();
      if (nds_planner_plan(planner, &s, (const double(*)[4])sp, goal, &plan, err, errlen))
        return -1;
      plan_wall += wall_s() - w0;
      out->plans++;
      char xerr[128];
      /* A plan the executor cannot meet within its limits or its workspace (the
       * planner's box: nd_exec_cfg_default) is dropped and the current
       * trajectory goes on, as the real executor does; so is a re-sent keypoint, whose
       * segment goes on rather than restarting (restarts can hold the robot still:
       * exec_loop.c). */
      if (!nd_exec_heading_to(&ex, t, plan.keys[0], ND_EXEC_SAME_KEY))
        (void)nd_exec_plan(&ex, &cfg->exec, t, plan.keys[0], plan.T, xerr, sizeof(xerr));
      next_plan += cfg->plan_period;
    }

    nd_exec_step(&ex, &cfg->exec, t, 0, sp);
    const double pos[2] = {d->qpos[world->ee_qpos[0]], d->qpos[world->ee_qpos[1]]};
    const double vel[2] = {d->qvel[world->ee_dof[0]], d->qvel[world->ee_dof[1]]};
    nds_ctrl_pid(ctrl, &pid, (const double(*)[4])sp, pos, vel, dt, force);
    d->qfrc_applied[world->ee_dof[0]] = force[0];
    d->qfrc_applied[world->ee_dof[1]] = force[1];
    mj_step(world->m, d);
    if (hook) hook(hook_ctx, world, d, (const double(*)[4])sp, force);
  }
  out->plan_ms = out->plans ? 1e3 * plan_wall / out->plans : 0.0;
  return 0;
}
