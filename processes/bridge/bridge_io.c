/* bridge_io: the bridge's inputs, outputs and reports (bridge_io.h). */
#include "bridge_io.h"

#include <stdio.h>
#include <string.h>

#include "nd_exec.h"
#include "nd_math.h"
#include "ndp_validate.h"

#define PROG "nudge-bridge"

_Static_assert(BRIDGE_WS_MARGIN >= ND_EXEC_WS_MARGIN,
               "the bridge must accept every setpoint the executor may send");

/* An EE_CMD that does not decode or is invalid (ndp_validate). */
static void refuse(void *user, const char *ch, const char *why) {
  bridge_io *io = user;
  io->st.received++;
  io->st.rejected++;
  ndp_refused(&io->refused, PROG, ch, why);
}

static void use_ee_cmd(void *user, const nudge_ee_cmd_t *msg) {
  bridge_io *io = user;
  io->st.received++;
  /* Tracking a command that the executor would never send moves the robot where nothing
   * checked it may go: refused like an invalid one, so the newest valid command goes on
   * being tracked until it is stale, and then the robot holds. The future's ends are
   * checked too: the robot follows them while the commander is silent. */
  const double *at[3] = {msg->p, msg->seg_key, msg->hold};
  static const char *const name[3] = {"p", "seg_key", "hold"};
  for (int i = 0; i < 3; i++)
    for (int k = 0; k < 2; k++) {
      if (at[i][k] >= io->ws.lo[k] - BRIDGE_WS_MARGIN && at[i][k] <= io->ws.hi[k] + BRIDGE_WS_MARGIN)
        continue;
      char why[256];
      snprintf(why, sizeof(why), "%s (%.3f, %.3f) is outside the workspace x [%.3f, %.3f], "
               "y [%.3f, %.3f] m plus its %.2f m margin", name[i], at[i][0], at[i][1],
               io->ws.lo[0], io->ws.hi[0], io->ws.lo[1], io->ws.hi[1], BRIDGE_WS_MARGIN);
      io->st.rejected++;
      ndp_refused(&io->refused_ws, PROG, "EE_CMD", why);
      return;
    }
  bridge_cmd c;
  for (int k = 0; k < 2; k++) {
    c.sp[k][ND_P] = msg->p[k];
    c.sp[k][ND_V] = msg->v[k];
    c.sp[k][ND_A] = msg->a[k];
    c.sp[k][ND_J] = msg->j[k];
  }
  /* The future on the command's own clock: 0 is its utime. */
  c.f.t_seg_end = 1e-6 * (double)(msg->seg_end_utime - msg->utime);
  c.f.t_brake = 1e-6 * (double)(msg->brake_utime - msg->utime);
  c.f.t_rest = 1e-6 * (double)(msg->rest_utime - msg->utime);
  memcpy(c.f.key, msg->seg_key, sizeof(c.f.key));
  memcpy(c.f.hold, msg->hold, sizeof(c.f.hold));
  c.arrival = ndp_mono();
  c.utime = msg->utime;
  c.seq = msg->seq;
  nd_mailbox_post(&io->b->cmd, &c, sizeof(c));
}

/* A new task releases an arm a reflex stopped, as the real robot resumes on the next
 * motion command after its error is acknowledged. */
static void use_task(void *user, const nudge_task_t *msg) {
  bridge_io *io = user;
  io->st.received++;
  if (msg->task_id == io->task_id) return;  /* re-sent for late joiners */
  io->task_id = msg->task_id;
  atomic_fetch_add(&io->b->resume_req, 1);
}

/* A PLACE goes to the loop once per place_id (it is re-sent until the object is seen
 * there), even when its re-sending outlasts a newer PLACE. A new one also releases an arm
 * a reflex stopped, as a new task does: resetting the scene acknowledges the error, and
 * the sphere has to move clear of the pose before the object can be put there. */
static void use_place(void *user, const nudge_place_t *msg) {
  bridge_io *io = user;
  io->st.received++;
  for (int k = 0; k < BRIDGE_PLACE_SEEN; k++)
    if (io->place_seen[k] == msg->place_id) return;
  io->place_seen[io->place_next] = msg->place_id;
  io->place_next = (io->place_next + 1) % BRIDGE_PLACE_SEEN;
  const bridge_place pl = {msg->place_id, {msg->x, msg->y, msg->yaw}, msg->clear, ndp_mono()};
  nd_mailbox_post(&io->b->place, &pl, sizeof(pl));
  atomic_fetch_add(&io->b->resume_req, 1);
}

NDP_INPUT(nudge_ee_cmd_t, ndp_check_ee_cmd, on_ee_cmd_raw, use_ee_cmd, refuse)
NDP_INPUT(nudge_place_t, ndp_check_place, on_place_raw, use_place, refuse)
NDP_INPUT(nudge_task_t, ndp_check_task, on_task_raw, use_task, refuse)

int bridge_io_subscribe(bridge_io *io, lcm_t *lcm, char *err, int errlen) {
  io->task_id = -1;
  for (int k = 0; k < BRIDGE_PLACE_SEEN; k++) io->place_seen[k] = -1;
  io->place_next = 0;
  if (!lcm_subscribe(lcm, NDP_CH_EE_CMD, on_ee_cmd_raw, io) ||
      !lcm_subscribe(lcm, NDP_CH_TASK, on_task_raw, io) ||
      !lcm_subscribe(lcm, NDP_CH_PLACE, on_place_raw, io)) {
    snprintf(err, errlen, "cannot subscribe to %s, %s and %s", NDP_CH_EE_CMD, NDP_CH_TASK,
             NDP_CH_PLACE);
    return -1;
  }
  return 0;
}

int bridge_io_publish(bridge_io *io, lcm_t *lcm) {
  int tag, n, failed = 0;
  while ((n = nd_ring_pop(&io->b->out, &tag, io->buf, sizeof(io->buf))) >= 0) {
    const char *ch = tag == BRIDGE_TAG_MOCAP       ? NDP_CH_MOCAP
                     : tag == BRIDGE_TAG_ARM_STATE ? NDP_CH_ARM_STATE
                                                   : NDP_CH_ROBOT_STATE;
    if (lcm_publish(lcm, ch, io->buf, (unsigned)n) == 0) io->st.published++;
    else failed++;
  }
  return failed;
}

void bridge_io_report(bridge_io *io, uint64_t *version, const nd_rtloop_stats *loop) {
  bridge_report *r = &io->rep;
  if (nd_mailbox_take(&io->b->report, version, r, sizeof(*r)) != (int)sizeof(*r)) return;
  if (r->holding != io->holding) {
    if (r->holding && r->apart)
      fprintf(stderr, PROG ": EE_CMD stamped over %g ms ahead of its arrival (the clocks "
              "disagree): the robot holds its setpoint at (%.4f, %.4f)\n",
              1e3 * BRIDGE_CMD_HORIZON, r->hold_pos[0], r->hold_pos[1]);
    else if (r->holding)
      fprintf(stderr, PROG ": %s: the robot holds at (%.4f, %.4f)\n",
              r->have_cmd ? "EE_CMD went stale" : "no EE_CMD yet", r->hold_pos[0],
              r->hold_pos[1]);
    else
      fprintf(stderr, PROG ": EE_CMD %s: tracking\n", io->had_cmd ? "back" : "arrived");
    io->holding = r->holding;
    io->had_cmd |= r->have_cmd;
  }
  const double now = ndp_mono();
  if (r->resets > io->resets_said && now - io->reset_said_at >= 5.0) {
    fprintf(stderr, PROG ": the world diverged (non-finite state): reset to the initial "
            "state (%lld resets)\n", (long long)r->resets);
    io->resets_said = r->resets;
    io->reset_said_at = now;
  }
  if (r->silent_events > io->silent_said && now - io->silent_said_at >= 5.0) {
    fprintf(stderr, PROG ": EE_CMD silent for over %g ms: the robot follows the trajectory the "
            "last one committed to (%lld times so far)\n", 1e3 * BRIDGE_CMD_HORIZON,
            (long long)r->silent_events);
    io->silent_said = r->silent_events;
    io->silent_said_at = now;
  }
  if (loop->skipped > io->skipped_said && now - io->skip_said_at >= 5.0) {
    fprintf(stderr, PROG ": the world loop stalled: %lld steps dropped so far\n",
            (long long)loop->skipped);
    io->skipped_said = loop->skipped;
    io->skip_said_at = now;
  }
  if (r->places > io->places_said || r->places_dropped > io->dropped_said) {
    const double *p = r->place_pose;
    if (r->places > io->places_said)
      fprintf(stderr, PROG ": PLACE %lld: the object placed at (%+.3f, %+.3f) m, yaw %+.1f deg, "
              "the sphere %.1f mm clear\n", (long long)r->place_id, p[0], p[1], p[2] * 180 / ND_PI,
              1e3 * r->place_gap);
    else
      fprintf(stderr, PROG ": PLACE %lld dropped: the sphere stayed %.1f mm from the object's "
              "sides at (%+.3f, %+.3f) m for %g s (a place needs it clear and at rest)\n",
              (long long)r->place_id, 1e3 * r->place_gap, p[0], p[1], NUDGE_PLACE_T_WAIT);
    io->places_said = r->places;
    io->dropped_said = r->places_dropped;
  }
  char name[48];
  if (r->stops > io->stops_said) {
    const nds_panda_reflex *x = &r->reflex;
    const bridge_sample *sa = r->stop_sample;
    static const char *const how[4] = {"held", "Taylor", "future", "future of the one before"};
    fprintf(stderr, PROG ": the robot stopped: %s %.4g beyond its limit %.4g; braking until the "
            "next task or PLACE (%lld stops); setpoint sampled from EE_CMD %lld (%s) %.2f ms "
            "after its time, the newest arrived %.2f ms before%s; the step before: EE_CMD %lld "
            "(%s) %.2f ms, %.2f ms%s\n", nds_panda_reflex_name(x, name, sizeof(name)), x->value,
            x->limit, (long long)r->stops, (long long)sa[0].cmd_seq, how[sa[0].how & 3],
            1e3 * sa[0].h, 1e3 * sa[0].silence, sa[0].join >= 0 ? ", joining" : "",
            (long long)sa[1].cmd_seq, how[sa[1].how & 3], 1e3 * sa[1].h, 1e3 * sa[1].silence,
            sa[1].join >= 0 ? ", joining" : "");
    io->stops_said = r->stops;
  }
  if (r->stopped)
    snprintf(io->state, sizeof(io->state), "stopped: %s",
             nds_panda_reflex_name(&r->reflex, name, sizeof(name)));
  else
    snprintf(io->state, sizeof(io->state), "%s", r->holding ? "holding" : "emulating");
  io->st.state = io->state;
}
