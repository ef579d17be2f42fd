/* exec_io: the executor's inputs, outputs and reports (exec_io.h). */
#include "exec_io.h"

#include <stdio.h>
#include <math.h>
#include <string.h>

#include "ndp_validate.h"

#define PROG "nudge-executor"

/* A refused input: undecodable, invalid (ndp_validate) or, for PLAN, made from a state
 * older than its segment; each kind has its own rate-limited log. */
static void refuse(void *user, const char *ch, const char *why) {
  exec_io *c = user;
  c->st.received++;
  c->st.rejected++;
  ndp_refused(strcmp(ch, NDP_CH_PLAN) ? &c->log_state : &c->log_plan, PROG, ch, why);
}

static void use_state(void *user, const nudge_robot_state_t *msg) {
  exec_io *c = user;
  c->st.received++;
  exec_loop_state_in in;
  in.t_arrive = ndp_sent_mono(msg->utime);
  memcpy(in.ee_pos, msg->ee_pos, sizeof in.ee_pos);
  in.stopped = msg->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED;
  nd_mailbox_post(&c->x->state, &in, (int)sizeof(in));
}

static void use_plan(void *user, const nudge_plan_t *msg) {
  exec_io *c = user;
  char why[160];
  c->st.received++;
  exec_loop_plan_in in;
  in.t_arrive = ndp_sent_mono(msg->utime);
  in.plan_id = msg->plan_id;
  in.utime = msg->utime;
  memcpy(in.start_p, msg->start_p, sizeof in.start_p);
  in.M = msg->M;  /* 1..ND_MAX_KEYS: ndp_check_plan */
  memcpy(in.keys, msg->keypoints, sizeof in.keys);
  /* Keypoint 0 is due T after the segment's start: start_utime when the plan names one
   * (its rollouts began there), else state_utime. A plan that arrives after that start
   * has its segment shortened by the delay, so the keypoint stays where the planner put it
   * in time; otherwise every plan would push the target further out and a robot
   * re-planned at 10-20 Hz would creep. Wall clocks of two hosts need to be synced for
   * this (same host here); the clamp to T/2 bounds the harm of a skewed clock. */
  const int64_t now_utime = ndp_utime();
  const int64_t start = msg->start_utime ? msg->start_utime : msg->state_utime;
  double late = 1e-6 * (double)(now_utime - start);
  /* A plan whose first keypoint was due before it arrived was made from a state the robot
   * has left (a planner stalled mid-plan, or one that planned on input it handled late):
   * even shortened, following it would move on stale information. One that starts later
   * than its own segment would last is not a plan for now. */
  if (late > msg->T || -late > msg->T) {
    snprintf(why, sizeof why, "plan %lld %s %.0f ms %s, more than its segment (%.0f ms)",
             (long long)msg->plan_id, late > 0 ? "is due from" : "starts", 1e3 * fabs(late),
             late > 0 ? "ago" : "ahead", 1e3 * msg->T);
    ndp_refused(&c->log_old, PROG, "PLAN", why);
    return;
  }
  in.t_start = in.t_arrive;
  if (late < 0.0) {
    /* Early: the segment starts at start_utime, on the executor's monotonic clock. */
    in.t_start = ndp_mono() - late;
    late = 0.0;
  }
  if (late > 0.5 * msg->T) late = 0.5 * msg->T;
  in.T = msg->T - late;
  nd_mailbox_post(&c->x->plan, &in, (int)sizeof(in));
}

NDP_INPUT(nudge_robot_state_t, ndp_check_robot_state, on_state_raw, use_state, refuse)
NDP_INPUT(nudge_plan_t, ndp_check_plan, on_plan_raw, use_plan, refuse)

int exec_io_subscribe(exec_io *io, lcm_t *lcm, char *err, int errlen) {
  if (!lcm_subscribe(lcm, NDP_CH_ROBOT_STATE, on_state_raw, io) ||
      !lcm_subscribe(lcm, NDP_CH_PLAN, on_plan_raw, io)) {
    snprintf(err, errlen, "cannot subscribe to " NDP_CH_ROBOT_STATE " and " NDP_CH_PLAN);
    return -1;
  }
  return 0;
}

int exec_io_publish(exec_io *io, lcm_t *lcm) {
  unsigned char buf[ND_RTIO_MAX];
  int tag, len, n = 0, bad = 0;
  while ((len = nd_ring_pop(&io->x->ring, &tag, buf, sizeof buf)) >= 0) {
    n++;
    if (tag != EXEC_LOOP_TAG_EE_CMD) continue;
    if (lcm_publish(lcm, NDP_CH_EE_CMD, buf, len) != 0) {
      bad = 1;
      continue;
    }
    io->st.published++;
  }
  /* More than one waiting means this thread fell behind the loop by that many periods. */
  if (n > io->backlog_max) io->backlog_max = n;
  return bad ? -1 : n;
}

static void say_stale(int bits, double timeout, double plan_timeout) {
  if (bits & EXEC_STALE_STATE)
    fprintf(stderr, PROG ": stale: no ROBOT_STATE for %g s: braking to rest and holding\n",
            timeout);
  else if (bits & EXEC_STALE_NO_PLAN)
    fprintf(stderr, PROG ": robot state received: holding there until a PLAN arrives\n");
  else
    fprintf(stderr, PROG ": stale: no PLAN for %g s: braking to rest and holding\n",
            plan_timeout);
}

int exec_io_report(exec_io *io, uint64_t *version) {
  exec_loop_report r;
  if (nd_mailbox_take(&io->x->report, version, &r, (int)sizeof r) != (int)sizeof r) return 0;
  exec_loop_report *last = &io->last;
  if (r.n_stale != last->n_stale || r.n_resume != last->n_resume) {
    const int64_t flips = (r.n_stale - last->n_stale) + (r.n_resume - last->n_resume);
    if (r.stale)
      say_stale(r.stale, io->timeout, io->plan_timeout);
    else
      fprintf(stderr, PROG ": fresh plan %lld: tracking again\n", (long long)r.plan_id);
    if (flips > 1)
      fprintf(stderr, PROG ": (%lld stale/fresh changes since the last report)\n",
              (long long)flips);
  }
  if (r.refused != last->refused) {
    char why[200];
    snprintf(why, sizeof why, "plan %lld: %s", (long long)r.refused_id, r.refused_why);
    /* Apart from the limits' refusals, so a planner often refused for those cannot
     * silence the first reports of plans outside the workspace. */
    ndp_refused(r.refused_rc == ND_EXEC_EBOX ? &io->log_box : &io->log_exec, PROG, "plan", why);
  }
  *last = r;
  io->st.state = r.mode < 0 ? "waiting" : nd_exec_mode_name(r.mode);
  io->st.rejected = io->log_state.count + io->log_plan.count + io->log_old.count + r.refused;
  return 1;
}
