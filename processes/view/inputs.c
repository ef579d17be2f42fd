/* inputs: nudge-view's input channels (view.h). Every message is validated as every other
 * process validates it (ndp_validate.h); a refused one is counted in the heartbeat, logged
 * rate-limited and never reaches what is drawn. The rest keeps the newest of each kind. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "view.h"

void view_inputs_init(view_inputs *in, double trail_s) {
  memset(in, 0, sizeof(*in));
  ndp_status_init(&in->st, PROG);
  in->trail_s = trail_s;
}

/* A refused input: undecodable, or invalid (ndp_validate, or what the view cannot draw). */
static void refuse(void *user, const char *ch, const char *why) {
  view_inputs *in = user;
  in->st.received++;
  in->st.rejected++;
  int k = 0;
  while (k < VIEW_NCH - 1 && strcmp(ch, view_channel(k))) k++;
  ndp_refused(&in->refused[k], PROG, ch, why);
}

/* When a message arrived: its log event's time, or live now. */
static int64_t arrival(const view_inputs *in) { return in->log_us ? in->log_us : ndp_utime(); }

static void use_mocap(void *user, const nudge_mocap_t *m) {
  view_inputs *in = user;
  in->st.received++;
  in->mocap = *m;
  in->have_mocap = 1;
}

static void use_task(void *user, const nudge_task_t *m) {
  view_inputs *in = user;
  in->st.received++;
  in->task = *m;
  in->have_task = 1;
}

static void use_plan(void *user, const nudge_plan_t *m) {
  view_inputs *in = user;
  const int64_t now = arrival(in);
  in->st.received++;
  in->plan = *m;
  in->have_plan = 1;
  for (int k = 0; k < 2; k++) {
    double *s = in->plan_s0[k];
    s[ND_A] = s[ND_J] = s[ND_V] = 0.0;
    if (in->have_cmd) {
      s[ND_P] = in->cmd.p[k];
      s[ND_V] = in->cmd.v[k];
      s[ND_A] = in->cmd.a[k];
    } else {
      s[ND_P] = in->have_mocap ? in->mocap.ee_pos[k] : m->keypoints[0][k];
    }
  }
  double age = 1e-6 * (double)(now - m->state_utime);
  if (!(age > 0.0)) age = 0.0;
  in->plan_seg0_T = m->T - fmin(age, 0.5 * m->T);
  in->plan_arrivals[in->plan_head] = now;
  in->plan_head = (in->plan_head + 1) % VIEW_RATE_CAP;
  if (in->plan_n < VIEW_RATE_CAP) in->plan_n++;
}

static void use_ee_cmd(void *user, const nudge_ee_cmd_t *m) {
  view_inputs *in = user;
  in->st.received++;
  in->cmd = *m;
  in->have_cmd = 1;
  /* A trail point every VIEW_TRAIL_DT of setpoint time; setpoint time going back (a
   * restarted executor) starts the trail anew. */
  const int64_t dt = (int64_t)(VIEW_TRAIL_DT * 1e6);
  if (in->trail_n) {
    const view_trail_pt *last = &in->trail[(in->trail_head + VIEW_TRAIL_CAP - 1) % VIEW_TRAIL_CAP];
    if (m->utime < last->utime) in->trail_n = 0;
    else if (m->utime - last->utime < dt) return;
  }
  view_trail_pt *p = &in->trail[in->trail_head];
  memcpy(p->p, m->p, sizeof p->p);
  p->utime = m->utime;
  in->trail_head = (in->trail_head + 1) % VIEW_TRAIL_CAP;
  if (in->trail_n < VIEW_TRAIL_CAP) in->trail_n++;
}

static void use_params(void *user, const nudge_params_t *m) {
  view_inputs *in = user;
  in->st.received++;
  in->params = *m;
  in->have_params = 1;
}

static void use_arm_state(void *user, const nudge_arm_state_t *m) {
  view_inputs *in = user;
  in->st.received++;
  memcpy(in->arm_q, m->q, sizeof in->arm_q);
  in->have_arm = 1;
}

/* Text the overlay's font can draw, shorter than cap: printable ASCII only, so a name
 * cannot carry control bytes or escapes into the picture or a log line. */
static int text_ok(const char *s, int cap, int empty_ok) {
  if (!s) return 0;
  int n = 0;
  for (; s[n]; n++)
    if (n >= cap - 1 || (unsigned char)s[n] < 0x20 || (unsigned char)s[n] > 0x7e) return 0;
  return n > 0 || empty_ok;
}

/* ndp_validate has no check for heartbeats (no process acts on them); the view draws
 * them, so it refuses what it could not draw or what no heartbeat holds. */
static int check_status(const nudge_status_t *m, char *why, int len) {
  if (m->utime <= 0) {
    snprintf(why, len, "utime = %lld is not a time", (long long)m->utime);
    return -1;
  }
  if (!text_ok(m->name, VIEW_TEXT, 0) || !text_ok(m->state, VIEW_TEXT, 1)) {
    snprintf(why, len, "name or state is not short printable text");
    return -1;
  }
  if (m->pid < 0 || m->received < 0 || m->published < 0 || m->rejected < 0 ||
      !isfinite(m->uptime) || m->uptime < 0.0) {
    snprintf(why, len, "a negative pid, counter or uptime");
    return -1;
  }
  return 0;
}

/* Raw subscription: lcm-gen's stub would decode a lying string length and crash
 * (ndp_decode_status). */
static void on_status(const lcm_recv_buf_t *rb, const char *ch, void *user) {
  view_inputs *in = user;
  char why[160];
  nudge_status_t m;
  if (ndp_decode_status(rb->data, (int)rb->data_size, &m, why, sizeof why)) {
    refuse(in, ch, why);
    return;
  }
  if (check_status(&m, why, sizeof why)) {
    refuse(in, ch, why);
    nudge_status_t_decode_cleanup(&m);
    return;
  }
  in->st.received++;
  /* One row per name (a restarted process keeps its row); a new name takes the row of
   * the one heard from least recently once the table is full. */
  view_beat *p = NULL;
  for (int i = 0; i < in->nprocs && !p; i++)
    if (!strcmp(in->procs[i].name, m.name)) p = &in->procs[i];
  if (!p) {
    if (in->nprocs < VIEW_MAX_PROCS) {
      p = &in->procs[in->nprocs++];
    } else {
      p = &in->procs[0];
      for (int i = 1; i < VIEW_MAX_PROCS; i++)
        if (in->procs[i].utime < p->utime) p = &in->procs[i];
    }
    memset(p, 0, sizeof *p);
  }
  /* Heartbeats of one process out of order: the newest stays. */
  if (m.pid != p->pid || m.utime >= p->utime) {
    snprintf(p->name, sizeof p->name, "%s", m.name);
    snprintf(p->state, sizeof p->state, "%s", m.state);
    p->pid = m.pid;
    p->utime = m.utime;
    p->rejected = m.rejected;
  }
  nudge_status_t_decode_cleanup(&m);
}

/* Beyond ndp_check_episode, what the overlay shows: finite numbers, a printable reason. */
static int check_episode_text(const nudge_episode_t *m, char *why, int len) {
  if (!(fabs(m->time) <= 1e6) || !(fabs(m->task_error) <= 1e6)) {
    snprintf(why, len, "time %g or task_error %g is not finite or beyond 1e6", m->time,
             m->task_error);
    return -1;
  }
  if (!text_ok(m->reason, VIEW_REASON, 1)) {
    snprintf(why, len, "reason is not short printable text");
    return -1;
  }
  return 0;
}

/* Raw subscription, as on_status (ndp_take_episode). */
static void on_episode(const lcm_recv_buf_t *rb, const char *ch, void *user) {
  view_inputs *in = user;
  char why[160];
  nudge_episode_t m;
  if (ndp_take_episode(rb->data, (int)rb->data_size, &m, why, sizeof why)) {
    refuse(in, ch, why);
    return;
  }
  if (check_episode_text(&m, why, sizeof why)) {
    refuse(in, ch, why);
  } else {
    in->st.received++;
    in->have_episode = 1;
    in->ep_task_id = m.task_id;
    in->ep_utime = m.utime;
    in->ep_event = m.event;
    in->ep_time = m.time;
    in->ep_error = m.task_error;
    snprintf(in->ep_reason, sizeof in->ep_reason, "%s", m.reason);
  }
  nudge_episode_t_decode_cleanup(&m);
}

NDP_INPUT(nudge_mocap_t, ndp_check_mocap, on_mocap, use_mocap, refuse)
NDP_INPUT(nudge_task_t, ndp_check_task, on_task, use_task, refuse)
NDP_INPUT(nudge_plan_t, ndp_check_plan, on_plan, use_plan, refuse)
NDP_INPUT(nudge_ee_cmd_t, ndp_check_ee_cmd, on_ee_cmd, use_ee_cmd, refuse)
NDP_INPUT(nudge_params_t, ndp_check_params, on_params, use_params, refuse)
NDP_INPUT(nudge_arm_state_t, ndp_check_arm_state, on_arm_state, use_arm_state, refuse)

/* The one table of channels: live subscriptions and a log's events go through it alike. */
static const struct {
  const char *channel;
  lcm_msg_handler_t handler;
} channels[VIEW_NCH] = {
    [VIEW_CH_MOCAP] = {NDP_CH_MOCAP, on_mocap},
    [VIEW_CH_TASK] = {NDP_CH_TASK, on_task},
    [VIEW_CH_PLAN] = {NDP_CH_PLAN, on_plan},
    [VIEW_CH_EE_CMD] = {NDP_CH_EE_CMD, on_ee_cmd},
    [VIEW_CH_PARAMS] = {NDP_CH_PARAMS, on_params},
    [VIEW_CH_STATUS] = {NDP_CH_STATUS, on_status},
    [VIEW_CH_EPISODE] = {NDP_CH_EPISODE, on_episode},
    [VIEW_CH_ARM_STATE] = {NDP_CH_ARM_STATE, on_arm_state},
};

const char *view_channel(int k) { return channels[k].channel; }

int view_inputs_subscribe(view_inputs *in, lcm_t *lcm, char *err, int errlen) {
  /* A frame keeps this thread from LCM for tens of ms: MOCAP (240 Hz) and EE_CMD (1 kHz)
   * get queues of ~0.5 s, so the drain after a frame ends on the newest message (LCM
   * drops the newest when a queue is full). */
  for (int i = 0; i < VIEW_NCH; i++) {
    lcm_subscription_t *s = lcm_subscribe(lcm, channels[i].channel, channels[i].handler, in);
    const int cap = i == VIEW_CH_EE_CMD ? 500 : i == VIEW_CH_MOCAP ? 128 : 0;
    if (!s || (cap && lcm_subscription_set_queue_capacity(s, cap))) {
      snprintf(err, errlen, "subscribing to %s failed", channels[i].channel);
      return -1;
    }
  }
  return 0;
}

void view_inputs_dispatch(view_inputs *in, const char *channel, const void *data, int size,
                          int64_t recv_utime) {
  for (int i = 0; i < VIEW_NCH; i++) {
    if (strcmp(channels[i].channel, channel)) continue;
    lcm_recv_buf_t rb = {(void *)data, (uint32_t)size, recv_utime, NULL};
    in->log_us = recv_utime;
    channels[i].handler(&rb, channel, in);
    in->log_us = 0;
    return;
  }
}

double view_inputs_plan_rate(const view_inputs *in, int64_t now_us) {
  const int64_t from = now_us - (int64_t)(VIEW_RATE_WINDOW * 1e6);
  int n = 0;
  for (int i = 0; i < in->plan_n; i++) {
    const int64_t t = in->plan_arrivals[(in->plan_head + VIEW_RATE_CAP - 1 - i) % VIEW_RATE_CAP];
    if (t > from && t <= now_us) n++;
  }
  return n / VIEW_RATE_WINDOW;
}
