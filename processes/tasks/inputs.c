/* inputs: the runner's channels (tasks.h), each message validated before use. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "tasks.h"

#define RATE_QUEUE 1000 /* queue of the 1 kHz channels: a second of them */

/* A refused input: undecodable, or invalid (ndp_validate); counted and logged,
 * rate-limited. */
static void refuse(void *user, const char *ch, const char *why) {
  tasks_io *io = user;
  io->st.rejected++;
  ndp_refused(&io->refused, PROG, ch, why);
}

/* Add the way from *last to p to *path once it is TASKS_PATH_STEP long, and move *last
 * there: summed frame by frame, motion capture's noise would count as travel (0.14 mm a
 * frame at 0.1 mm per axis: 0.17 m over 5 s at rest). */
static void path_step(double *path, double last[2], const double *p, int have_last) {
  const double d = have_last ? hypot(p[0] - last[0], p[1] - last[1]) : INFINITY;
  if (have_last && d < TASKS_PATH_STEP) return;
  if (have_last) *path += d;
  last[0] = p[0], last[1] = p[1];
}

static void use_mocap(void *user, const nudge_mocap_t *m) {
  tasks_io *io = user;
  io->last = *m;
  io->t_last = ndp_mono();
  io->frames++;
  io->fresh = 1;
  io->st.received++;
  tasks_running *r = &io->run;
  if (r->id >= 0) {
    path_step(&r->obj_path, r->last_obj, m->obj_pos, r->have_last);
    path_step(&r->ee_path, r->last_ee, m->ee_pos, r->have_last);
    r->have_last = 1;
    if (!r->moved && tasks_frame_shift(m, &r->start) >= TASKS_MOVED) {
      r->moved = 1;
      r->moved_at = io->t_last;
    }
  }
  if (io->buf) {
    double pose[ND_ROLLOUT_OBJ];
    memcpy(pose, m->obj_pos, 3 * sizeof(double));
    memcpy(pose + 3, m->obj_quat, 4 * sizeof(double));
    nd_recorder_frame(&io->buf->rec, m->utime, pose);
  }
}

static void use_robot_state(void *user, const nudge_robot_state_t *m) {
  tasks_io *io = user;
  io->st.received++;
  /* A robot still stopped from the last task resumes when this task's TASK reaches the
   * bridge: only a stop after it has moved again is this task's. */
  if (m->mode != NUDGE_ROBOT_STATE_T_MODE_STOPPED && io->run.id >= 0) io->run.resumed = 1;
  const double v = hypot(m->ee_vel[0], m->ee_vel[1]);
  if (v >= REST_SPEED) io->ee_moving_at = ndp_mono();
  if (io->run.id >= 0 && v > io->run.ee_speed_max) io->run.ee_speed_max = v;
  if (m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED && io->run.id >= 0 && io->run.resumed &&
      !io->run.stopped) {
    io->run.stopped = 1;
    io->run.reflex = m->reflex;
    io->run.reflex_joint = m->reflex_joint;
  }
  /* A stop between tasks (the release after one, the sphere kept clear or parked) ends no
   * task, but the robot made it all the same: count it, and say when it came. */
  const int stopped = m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED;
  if (stopped && io->robot_stopped == 0 && io->run.id < 0) {
    io->stops_between++;
    const int placing = strcmp(io->st.state, "placing") == 0;
    fprintf(stderr, PROG ": the robot stopped on a reflex %s: %s\n",
            placing ? "while placing" : "between tasks",
            tasks_reflex_name(m->reflex, m->reflex_joint));
  }
  io->robot_stopped = stopped;
  if (!io->buf) return;
  nd_rec_state *s = &io->buf->rs;
  s->seq = m->seq;
  s->utime = m->utime;
  memcpy(s->ee_pos, m->ee_pos, sizeof(s->ee_pos));
  memcpy(s->ee_vel, m->ee_vel, sizeof(s->ee_vel));
  memcpy(s->force, m->ee_force, sizeof(s->force));
  io->buf->have_rs = 1;
  nd_recorder_state(&io->buf->rec, s);
}

static void use_ee_cmd(void *user, const nudge_ee_cmd_t *m) {
  tasks_io *io = user;
  io->st.received++;
  if (m->mode != NUDGE_EE_CMD_T_MODE_HOLDING) io->cmd_moving_at = ndp_mono();
  if (io->run.id >= 0) {
    const double v = hypot(m->v[0], m->v[1]);
    if (v > io->run.cmd_speed_max) io->run.cmd_speed_max = v;
  }
  if (!io->buf) return;
  nd_rec_setpoint sp;
  memcpy(sp.p, m->p, sizeof(sp.p));
  memcpy(sp.v, m->v, sizeof(sp.v));
  memcpy(sp.a, m->a, sizeof(sp.a));
  nd_recorder_setpoint(&io->buf->rec, &sp);
}

static void use_params(void *user, const nudge_params_t *m) {
  tasks_io *io = user;
  io->st.received++;
  memcpy(io->buf->theta, m->theta_mean, sizeof(io->buf->theta));
  io->buf->theta_version = m->version;
  io->buf->params_n = m->buffer_size;
}

static void use_plan(void *user, const nudge_plan_t *m) {
  tasks_io *io = user;
  io->st.received++;
  if (m->task_id != io->run.id) return;
  io->run.plans++;
  if (io->nages < MAX_PLAN_AGES) io->ages[io->nages++] = 1e-3 * (double)(m->utime - m->state_utime);
}

NDP_INPUT(nudge_mocap_t, ndp_check_mocap, on_mocap_raw, use_mocap, refuse)
NDP_INPUT(nudge_robot_state_t, ndp_check_robot_state, on_robot_state_raw, use_robot_state, refuse)
NDP_INPUT(nudge_ee_cmd_t, ndp_check_ee_cmd, on_ee_cmd_raw, use_ee_cmd, refuse)
NDP_INPUT(nudge_params_t, ndp_check_params, on_params_raw, use_params, refuse)
NDP_INPUT(nudge_plan_t, ndp_check_plan, on_plan_raw, use_plan, refuse)

int tasks_subscribe(tasks_io *io, lcm_t *lcm, char *err, int errlen) {
  /* The runner handles input every 20 ms and appends (one fdatasync) between tasks: a
   * default queue of 30 would drop 1 kHz messages (the newest, as seq gaps). ROBOT_STATE
   * always: it says when a reflex stopped the robot; EE_CMD always: its top speed. */
  io->run.id = -1;
  io->robot_stopped = -1;  /* unknown: a stop before the runner started is not counted */
  io->cmd_moving_at = io->ee_moving_at = -INFINITY;
  lcm_subscription_t *rs = lcm_subscribe(lcm, NDP_CH_ROBOT_STATE, on_robot_state_raw, io);
  lcm_subscription_t *plan = lcm_subscribe(lcm, NDP_CH_PLAN, on_plan_raw, io);
  lcm_subscription_t *cmd = lcm_subscribe(lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, io);
  if (!lcm_subscribe(lcm, NDP_CH_MOCAP, on_mocap_raw, io) || !rs || !plan || !cmd ||
      lcm_subscription_set_queue_capacity(rs, RATE_QUEUE) ||
      lcm_subscription_set_queue_capacity(cmd, RATE_QUEUE) ||
      lcm_subscription_set_queue_capacity(plan, 100)) {
    snprintf(err, errlen, "subscribing to MOCAP, ROBOT_STATE, EE_CMD and PLAN failed");
    return -1;
  }
  if (io->buf && !lcm_subscribe(lcm, NDP_CH_PARAMS, on_params_raw, io)) {
    snprintf(err, errlen, "subscribing to PARAMS failed");
    return -1;
  }
  return 0;
}
