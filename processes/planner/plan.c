/* plan: one plan from the newest inputs, published on PLAN (planner.h). */
#include <stdio.h>
#include <string.h>

#include "planner.h"

/* Plan from the newest inputs and publish. Return 0, or -1 with a message (LCM failure). */
int planner_plan_once(planner_proc *p, double now, char *err, int errlen) {
  const planner_opts *o = p->o;
  nds_state s;
  memcpy(s.obj_pos, p->mocap.obj_pos, sizeof(s.obj_pos));
  memcpy(s.obj_quat, p->mocap.obj_quat, sizeof(s.obj_quat));
  nd_objest_velocity(&p->est, s.obj_vel);
  /* The end-effector from the robot's own state: fresher than mocap and with velocity. */
  for (int k = 0; k < 2; k++) {
    s.ee_pos[k] = p->rs.ee_pos[k];
    s.ee_vel[k] = p->rs.ee_vel[k];
  }
  /* The executor starts the plan's first segment from its setpoint, so the rollouts must
   * too. No setpoint yet, or the executor has gone quiet: the robot holds where it is. */
  double sp0[2][4];
  const int cmd_ok = ndp_input_fresh(&p->in_cmd, now, o->state_timeout);
  for (int k = 0; k < 2; k++) {
    sp0[k][0] = cmd_ok ? p->cmd.p[k] : p->rs.ee_pos[k];
    sp0[k][1] = cmd_ok ? p->cmd.v[k] : 0.0;
    sp0[k][2] = cmd_ok ? p->cmd.a[k] : 0.0;
    sp0[k][3] = cmd_ok ? p->cmd.j[k] : 0.0;
  }
  const nd_goal goal = {.x = p->task.goal_x, .y = p->task.goal_y, .yaw = p->task.goal_yaw};

  nds_plan plan;
  char why[160];
  double t0 = ndp_mono();
  if (nds_planner_plan(p->planner, &s, (const double(*)[4])sp0, &goal, &plan, why,
                       sizeof(why))) {
    /* Inputs are validated, so this is a non-finite estimate: skip this round. */
    planner_reject(p, "plan input", why);
    return 0;
  }
  double ms = 1e3 * (ndp_mono() - t0);

  nudge_plan_t m;
  memset(&m, 0, sizeof(m));
  m.utime = ndp_utime();
  m.plan_id = ++p->plan_id;
  m.task_id = p->task.task_id;
  m.state_utime = p->mocap.utime;
  m.M = (int8_t)plan.M;
  for (int k = 0; k < plan.M && k < NUDGE_PLAN_T_MAX_KEYPOINTS; k++)
    memcpy(m.keypoints[k], plan.keys[k], 4 * sizeof(double));
  m.T = plan.T;
  m.cost = plan.cost;
  m.task_error = plan.task_error;
  memcpy(m.predicted, plan.predicted, sizeof(m.predicted));
  m.iterations = o->iters;
  m.evals = plan.evals;
  m.plan_ms = ms;
  m.theta_version = p->theta_version;
  if (nudge_plan_t_publish(p->lcm, NDP_CH_PLAN, &m) != 0) {
    snprintf(err, errlen, "publishing on %s failed", NDP_CH_PLAN);
    return -1;
  }
  p->st.published++;
  p->task_plans++;
  p->task_ms_sum += ms;
  if (ms > p->task_ms_max) p->task_ms_max = ms;
  return 0;
}

