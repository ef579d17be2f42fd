/* inputs: nudge-planner's input channels (planner.h): each message validated, counted and
 * kept as the newest of its kind; TASK, EPISODE and PARAMS change the task and theta. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_math.h"
#include "planner.h"

void planner_reject(planner_proc *p, const char *channel, const char *why) {
  p->st.rejected++;
  ndp_refused(&p->rejected, PROG, channel, why);
}

/* A refused input: undecodable, or invalid (ndp_validate). */
static void refuse(void *user, const char *ch, const char *why) {
  planner_proc *p = user;
  p->st.received++;
  planner_reject(p, ch, why);
}

static void use_mocap(void *user, const nudge_mocap_t *m) {
  planner_proc *p = user;
  p->st.received++;
  /* A frame not newer than the last (a restarted publisher, a stepped clock) restarts the
   * estimate (nd_objest_add); otherwise a jump in seq counts the frames lost. */
  if (p->in_mocap.have && m->utime > p->mocap.utime && m->seq > p->mocap.seq + 1)
    p->mocap_lost += m->seq - p->mocap.seq - 1;
  p->mocap = *m;
  ndp_input_got(&p->in_mocap, m->utime);
  nd_objest_add(&p->est, m->utime, m->obj_pos, m->obj_quat);
}

static void use_robot_state(void *user, const nudge_robot_state_t *m) {
  planner_proc *p = user;
  p->st.received++;
  p->rs = *m;
  ndp_input_got(&p->in_rs, m->utime);
  if (m->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED) p->stopped_at = ndp_mono();
}

static void use_ee_cmd(void *user, const nudge_ee_cmd_t *m) {
  planner_proc *p = user;
  p->st.received++;
  p->cmd = *m;
  ndp_input_got(&p->in_cmd, m->utime);
}

void planner_task_summary(planner_proc *p, const char *how) {
  double dt = ndp_mono() - p->task_t0, live = dt - p->task_stale;
  fprintf(stderr,
          PROG ": task %lld %s after %.2f s: %lld plans, %.1f plans/s over %.2f s of fresh "
          "state, plan %.1f ms mean / %.1f max, candidates beyond the limits %.1f %% / the "
          "arm's %.1f %%, %.1f simulated per plan, %.1f redrawn, %lld mocap frames lost, "
          "%lld queue overflows\n",
          (long long)p->task.task_id, how, dt, (long long)p->task_plans,
          live > 0 ? p->task_plans / live : 0.0, live, p->task_plans ? p->task_ms_sum / p->task_plans : 0.0,
          p->task_ms_max, p->task_evals ? 100.0 * p->task_over_limits / p->task_evals : 0.0,
          p->task_evals ? 100.0 * p->task_over_arm / p->task_evals : 0.0,
          p->task_plans ? (double)p->task_rollouts / p->task_plans : 0.0,
          p->task_plans ? (double)p->task_redrawn / p->task_plans : 0.0,
          (long long)(p->mocap_lost - p->task_mocap_lost0),
          (long long)(p->overflows - p->task_overflows0));
}

/* A new PLACE: the sphere is kept clear of the pose until the object is seen there. */
static void use_place(void *user, const nudge_place_t *m) {
  planner_proc *p = user;
  p->st.received++;
  if (m->place_id == p->place.place_id) return;  /* re-sent until the object is there */
  p->place = *m;
  p->place_due = p->place_pending = 1;
  p->place_at = ndp_mono();
  p->parking = m->park;
  p->park_n = p->park_next = p->park_tries = 0;
}

static void use_task(void *user, const nudge_task_t *m) {
  planner_proc *p = user;
  p->st.received++;
  /* A repeated TASK (re-sent for late joiners) neither restarts the warm start nor
   * revives a task whose end we have seen; its goal is the same by contract. */
  if ((p->active && m->task_id == p->task.task_id) ||
      (p->have_ended && m->task_id == p->ended_id))
    return;
  if (p->active) planner_task_summary(p, "superseded");
  p->task = *m;
  p->active = 1;
  p->release_due = 0;
  p->keep_clear = 0;
  p->parking = 0;
  p->task_t0 = ndp_mono();
  p->task_plans = 0;
  p->task_ms_sum = p->task_ms_max = p->task_stale = 0.0;
  p->task_evals = p->task_over_limits = p->task_over_arm = 0;
  p->task_rollouts = p->task_redrawn = 0;
  p->edge_warned = 0;
  p->task_mocap_lost0 = p->mocap_lost;
  p->task_overflows0 = p->overflows;
  /* A new task starts cold (set_v_max forgets the warm start), within its own speed limit
   * (validated: cannot fail). */
  char err[160];
  if (nds_planner_set_v_max(p->planner, m->v_max, err, sizeof(err)))
    fprintf(stderr, PROG ": task %lld: %s\n", (long long)m->task_id, err);
  fprintf(stderr, PROG ": task %lld started: goal (%+.3f, %+.3f) m, yaw %+.1f deg, eps %g, "
          "limit %.1f s, speed limit %g m/s\n", (long long)m->task_id, m->goal_x, m->goal_y,
          m->goal_yaw * 180.0 / ND_PI, m->eps, m->time_limit,
          nds_planner_config(p->planner)->v_max);
}

/* Raw subscription: lcm-gen's stub would decode a lying string length and crash
 * (ndp_decode_episode). */
static void on_episode(const lcm_recv_buf_t *rb, const char *ch, void *user) {
  planner_proc *p = user;
  char why[160];
  nudge_episode_t m;
  if (ndp_take_episode(rb->data, (int)rb->data_size, &m, why, sizeof(why))) {
    refuse(p, ch, why);
    return;
  }
  p->st.received++;
  if (m.event != NUDGE_EPISODE_T_EVENT_START) {
    p->have_ended = 1;
    p->ended_id = m.task_id;
    if (p->active && m.task_id == p->task.task_id) {
      p->active = 0;
      p->release_due = 1;
      planner_task_summary(p, m.event == NUDGE_EPISODE_T_EVENT_SUCCESS   ? "succeeded"
                              : m.event == NUDGE_EPISODE_T_EVENT_TIMEOUT ? "timed out"
                              : m.event == NUDGE_EPISODE_T_EVENT_STOPPED ? "ended in a reflex stop"
                                                                          : "was rejected");
    }
  }
  nudge_episode_t_decode_cleanup(&m);
}

static void use_params(void *user, const nudge_params_t *m) {
  planner_proc *p = user;
  char why[160];
  p->st.received++;
  if (m->version == p->theta_version) return;
  if (nds_planner_set_theta(p->planner, m->theta_mean, why, sizeof(why))) {
    planner_reject(p, NDP_CH_PARAMS, why);
    return;
  }
  p->theta_version = m->version;
  char th[200];
  nd_theta_str(m->theta_mean, ", ", th, sizeof(th));
  fprintf(stderr, PROG ": theta version %lld: (%s)\n", (long long)m->version, th);
}

NDP_INPUT(nudge_mocap_t, ndp_check_mocap, on_mocap_raw, use_mocap, refuse)
NDP_INPUT(nudge_robot_state_t, ndp_check_robot_state, on_robot_state_raw, use_robot_state, refuse)
NDP_INPUT(nudge_ee_cmd_t, ndp_check_ee_cmd, on_ee_cmd_raw, use_ee_cmd, refuse)
NDP_INPUT(nudge_task_t, ndp_check_task, on_task_raw, use_task, refuse)
NDP_INPUT(nudge_params_t, ndp_check_params, on_params_raw, use_params, refuse)
NDP_INPUT(nudge_place_t, ndp_check_place, on_place_raw, use_place, refuse)

/* ---------------------------------------------------------------------------------- */


int planner_subscribe(planner_proc *p, char *err, int errlen) {
  /* A plan keeps this thread away from LCM for tens of ms, and LCM drops the NEWEST
   * message when a subscription's queue (default 30) is full: at 1 kHz the drain after a
   * plan would then hand over state from the plan's first 30 ms. Queues of ~0.5 s of
   * input keep the newest; a longer stall is detected (ndp_input_drained). */
  p->in_mocap.cap = 128;
  p->in_rs.cap = p->in_cmd.cap = 500;
  lcm_subscription_t *s_mocap = lcm_subscribe(p->lcm, NDP_CH_MOCAP, on_mocap_raw, p);
  lcm_subscription_t *s_rs = lcm_subscribe(p->lcm, NDP_CH_ROBOT_STATE, on_robot_state_raw, p);
  lcm_subscription_t *s_cmd = lcm_subscribe(p->lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, p);
  if (!s_mocap || !s_rs || !s_cmd || !lcm_subscribe(p->lcm, NDP_CH_TASK, on_task_raw, p) ||
      !lcm_subscribe(p->lcm, NDP_CH_PARAMS, on_params_raw, p) ||
      !lcm_subscribe(p->lcm, NDP_CH_PLACE, on_place_raw, p) ||
      !lcm_subscribe(p->lcm, NDP_CH_EPISODE, on_episode, p) ||
      lcm_subscription_set_queue_capacity(s_mocap, p->in_mocap.cap) ||
      lcm_subscription_set_queue_capacity(s_rs, p->in_rs.cap) ||
      lcm_subscription_set_queue_capacity(s_cmd, p->in_cmd.cap)) {
    snprintf(err, errlen, "subscribing to the input channels failed");
    return -1;
  }
  return 0;
}

void planner_drained(planner_proc *p) {
  const int n = ndp_input_drained(&p->in_mocap) + ndp_input_drained(&p->in_rs) +
                ndp_input_drained(&p->in_cmd);
  p->overflows += n;
  /* Said at once, not only in the task's summary: what came after is gone. */
  if (n) ndp_lost(&p->lost, PROG, "the newest input: a queue filled while a plan ran");
}

/* 1 if a plan may start now: mocap and robot state fresh, and the setpoint not known to
 * be behind while the executor is live (its next message is a millisecond away).
 * Ages count from each message's sending, so input that queued up while this process
 * was busy or stopped is as old as it is: after a stall the planner waits for new state
 * instead of planning from what the socket kept (the oldest, once it overflowed). */
int planner_state_fresh(const planner_proc *p, double now) {
  const double to = p->o->state_timeout;
  return ndp_input_fresh(&p->in_mocap, now, to) && ndp_input_fresh(&p->in_rs, now, to) &&
         !(p->in_cmd.behind && now - p->in_cmd.t <= to);
}

