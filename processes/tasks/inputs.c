/* inputs: the runner's channels (tasks.h), each message validated before use. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "tasks.h"

#define RATE_QUEUE 1000 /* queue of the 1 kHz channels: a second of them */

/* Count a refused message in the heartbeat and log it, rate-limited. */
static void refuse(tasks_io *io, const char *what, const char *why) {
  io->st.rejected++;
  ndp_refused(&io->refused, PROG, what, why);
}

static void on_mocap(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_mocap_t *m,
                     void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_mocap(m, why, sizeof(why))) {
    refuse(io, "MOCAP frame", why);
    return;
  }
  io->last = *m;
  io->t_last = ndp_mono();
  io->frames++;
  io->fresh = 1;
  io->st.received++;
  tasks_running *r = &io->run;
  if (r->id >= 0) {
    if (r->have_last) {
      r->obj_path += hypot(m->obj_pos[0] - r->last_obj[0], m->obj_pos[1] - r->last_obj[1]);
      r->ee_path += hypot(m->ee_pos[0] - r->last_ee[0], m->ee_pos[1] - r->last_ee[1]);
    }
    memcpy(r->last_obj, m->obj_pos, sizeof(r->last_obj));
    memcpy(r->last_ee, m->ee_pos, sizeof(r->last_ee));
    r->have_last = 1;
  }
  if (io->buf) {
    double pose[ND_ROLLOUT_OBJ];
    memcpy(pose, m->obj_pos, 3 * sizeof(double));
    memcpy(pose + 3, m->obj_quat, 4 * sizeof(double));
    nd_recorder_frame(&io->buf->rec, m->utime, pose);
  }
}

static void on_robot_state(const lcm_recv_buf_t *rbuf, const char *ch,
                           const nudge_robot_state_t *m, void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_robot_state(m, why, sizeof(why))) {
    refuse(io, "ROBOT_STATE", why);
    return;
  }
  io->st.received++;
  if (m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED && io->run.id >= 0 && !io->run.stopped) {
    io->run.stopped = 1;
    io->run.reflex = m->reflex;
    io->run.reflex_joint = m->reflex_joint;
  }
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

static void on_ee_cmd(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_ee_cmd_t *m,
                      void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_ee_cmd(m, why, sizeof(why))) {
    refuse(io, "EE_CMD", why);
    return;
  }
  io->st.received++;
  nd_rec_setpoint sp;
  memcpy(sp.p, m->p, sizeof(sp.p));
  memcpy(sp.v, m->v, sizeof(sp.v));
  memcpy(sp.a, m->a, sizeof(sp.a));
  nd_recorder_setpoint(&io->buf->rec, &sp);
}

static void on_params(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_params_t *m,
                      void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_params(m, why, sizeof(why))) {
    refuse(io, "PARAMS", why);
    return;
  }
  io->st.received++;
  memcpy(io->buf->theta, m->theta_mean, sizeof(io->buf->theta));
  io->buf->theta_version = m->version;
  io->buf->params_n = m->buffer_size;
}

static void on_plan(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_plan_t *m,
                    void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_plan(m, why, sizeof(why))) {
    refuse(io, "PLAN", why);
    return;
  }
  io->st.received++;
  if (m->task_id != io->run.id) return;
  io->run.plans++;
  if (io->nages < MAX_PLAN_AGES) io->ages[io->nages++] = 1e-3 * (double)(m->utime - m->state_utime);
}

/* Bytes on a typed channel that are not one message of its type. */
static void undecodable(void *user, const char *ch, const char *why) {
  refuse(user, ch, why);
}

NDP_TYPED_HANDLER(nudge_mocap_t, on_mocap_raw, on_mocap, undecodable)
NDP_TYPED_HANDLER(nudge_robot_state_t, on_robot_state_raw, on_robot_state, undecodable)
NDP_TYPED_HANDLER(nudge_ee_cmd_t, on_ee_cmd_raw, on_ee_cmd, undecodable)
NDP_TYPED_HANDLER(nudge_params_t, on_params_raw, on_params, undecodable)
NDP_TYPED_HANDLER(nudge_plan_t, on_plan_raw, on_plan, undecodable)

int tasks_subscribe(tasks_io *io, lcm_t *lcm, char *err, int errlen) {
  /* The runner handles input every 20 ms and appends (one fdatasync) between tasks: a
   * default queue of 30 would drop 1 kHz messages (the newest, as seq gaps). ROBOT_STATE
   * always: it says when a reflex stopped the robot. */
  io->run.id = -1;
  lcm_subscription_t *rs = lcm_subscribe(lcm, NDP_CH_ROBOT_STATE, on_robot_state_raw, io);
  lcm_subscription_t *plan = lcm_subscribe(lcm, NDP_CH_PLAN, on_plan_raw, io);
  if (!lcm_subscribe(lcm, NDP_CH_MOCAP, on_mocap_raw, io) || !rs || !plan ||
      lcm_subscription_set_queue_capacity(rs, RATE_QUEUE) ||
      lcm_subscription_set_queue_capacity(plan, 100)) {
    snprintf(err, errlen, "subscribing to MOCAP, ROBOT_STATE and PLAN failed");
    return -1;
  }
  if (!io->buf) return 0;
  lcm_subscription_t *cmd = lcm_subscribe(lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, io);
  if (!cmd || !lcm_subscribe(lcm, NDP_CH_PARAMS, on_params_raw, io) ||
      lcm_subscription_set_queue_capacity(cmd, RATE_QUEUE)) {
    snprintf(err, errlen, "subscribing to EE_CMD and PARAMS failed");
    return -1;
  }
  return 0;
}
