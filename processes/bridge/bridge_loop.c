/* bridge_loop: one step of the bridge (bridge_loop.h). */
#include "bridge_loop.h"

#include <math.h>
#include <string.h>

#include "nd_snap.h"
#include "nudge/nudge_arm_state_t.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_robot_state_t.h"

void bridge_loop_init(bridge_loop *b, nds_world *w, double cmd_timeout) {
  memset(b, 0, sizeof(*b));
  b->awake_since = -INFINITY;
  b->world = w;
  b->cmd_timeout = cmd_timeout;
  nd_mailbox_init(&b->cmd);
  nd_mailbox_init(&b->report);
  nd_mailbox_init(&b->place);
  nd_ring_init(&b->out);
  atomic_init(&b->resume_req, 0);
  b->holding = 1;  /* no command yet: hold the start position */
  nds_world_ee(w, b->hold);
  /* lcm-gen computes a type's hash lazily on first use: do it here, not in the loop. */
  (void)nudge_robot_state_t_encoded_size(&(nudge_robot_state_t){0});
  (void)nudge_mocap_t_encoded_size(&(nudge_mocap_t){0});
  (void)nudge_arm_state_t_encoded_size(&(nudge_arm_state_t){0});
  bridge_loop_report_post(b);
}

void bridge_loop_report_post(bridge_loop *b) {
  b->rep.holding = b->holding;
  b->rep.have_cmd = b->have_cmd;
  b->rep.hold_pos[0] = b->hold[0];
  b->rep.hold_pos[1] = b->hold[1];
  nd_mailbox_post(&b->report, &b->rep, sizeof(b->rep));
}

/* Command c's trajectory h s after its time into sp (bridge_loop.h: Taylor terms near it,
 * its future beyond; h < 0 only down to -BRIDGE_CMD_HORIZON, by the terms). */
static void sample(const bridge_cmd *c, double h, double sp[2][4]) {
  if (h > BRIDGE_CMD_TAYLOR) {
    nd_exec_future_eval((const double(*)[4])c->sp, 0.0, &c->f, h, sp);
    return;
  }
  h = fmax(h, -BRIDGE_CMD_HORIZON);
  for (int k = 0; k < 2; k++) {
    const double *s = c->sp[k], p = s[ND_P], v = s[ND_V], a = s[ND_A], j = s[ND_J];
    sp[k][ND_P] = p + h * (v + h * (a / 2 + h * j / 6));
    sp[k][ND_V] = v + h * (a + h * j / 2);
    sp[k][ND_A] = a + h * j;
    sp[k][ND_J] = j;
  }
}

/* Add the join's offset at utime to sp, first starting one if this step samples another
 * command than the step before did from a future: the offset is what separates the two
 * there, 0 when the new command goes on along the old one's trajectory (BRIDGE_JOIN_S). */
static void join(bridge_loop *b, int64_t utime, double sp[2][4]) {
  bridge_sample *sa = &b->sample[0];
  const bridge_sample *before = &b->sample[1];
  double off[2][4];
  sa->join = -1;
  if (sa->how == BRIDGE_SAMPLE_HOLD) {
    b->joining = 0;
    return;
  }
  if (b->joining) {
    const double t = 1e-6 * (double)(utime - b->join_utime);
    if (t >= b->join.T) b->joining = 0;
    else nd_snap_seg_eval(&b->join, t, off), sa->join = t;
  }
  const bridge_cmd *now = sa->how == BRIDGE_SAMPLE_PREV ? &b->prev : &b->last;
  const int other = now->seq != b->src.seq || now->utime != b->src.utime;
  if (other && before->how != BRIDGE_SAMPLE_HOLD && before->h > BRIDGE_CMD_TAYLOR) {
    /* Where the step before's trajectory (and offset) goes on to, less where this one is. */
    double was[2][4];
    sample(&b->src, 1e-6 * (double)(utime - b->src.utime), was);
    for (int k = 0; k < 2; k++)
      for (int i = 0; i < 4; i++) was[k][i] += (sa->join >= 0 ? off[k][i] : 0.0) - sp[k][i];
    const double miss = hypot(was[0][ND_P], was[1][ND_P]);
    b->joining = miss <= BRIDGE_JOIN_MAX;
    if (b->joining) {
      nd_snap_seg_make(&b->join, (const double(*)[4])was, (const double[2]){0, 0},
                       (const double[2]){0, 0}, BRIDGE_JOIN_S);
      b->join_utime = utime;
      b->rep.joins++;
      memcpy(off, was, sizeof off);
      sa->join = 0;
    }
  }
  if (other) b->src = *now;
  if (!b->joining) return;
  for (int k = 0; k < 2; k++)
    for (int i = 0; i < 4; i++) sp[k][i] += off[k][i];
}

/* The setpoint at utime: the newest command's trajectory until it is stale, or the one
 * before it for a step before its time; hold the last setpoint while the stamps disagree
 * with the robot's clock, and where the sphere is once the commands are stale or before
 * the first (doc/lab-world.md#commands). Return 1 if the hold state changed. */
static int setpoint(bridge_loop *b, double now, int64_t utime, double sp[2][4]) {
  bridge_cmd c;
  if (nd_mailbox_take(&b->cmd, &b->cmd_version, &c, sizeof(c)) == (int)sizeof(c)) {
    /* A step catching up after a stall may get several commands stamped ahead of it: the
     * one it follows is the newest its time has reached, not merely the one before. */
    if (b->have_cmd && (b->last.utime <= utime || !b->have_prev)) {
      b->prev = b->last;
      b->have_prev = 1;
    }
    b->last = c;
    b->have_cmd = 1;
    b->silent = 0;
  }
  const double h = (double)(utime - b->last.utime) * 1e-6, silence = now - b->last.arrival;
  const int timely = b->have_cmd && (silence <= b->cmd_timeout ||
                                     now - b->awake_since <= b->cmd_timeout);
  const int fresh = timely && h - silence <= BRIDGE_CMD_HORIZON;
  int changed = 0;
  if (fresh && b->holding) {
    b->holding = 0;
    b->rep.apart = 0;
    nds_world_motion_start(b->world);
    changed = 1;
  } else if (!fresh && !b->holding) {
    /* The robot's own stop, not a commanded motion: its reflexes start afresh from it. */
    b->holding = 1;
    nds_world_motion_start(b->world);
    b->rep.apart = timely;
    if (timely) b->hold[0] = b->sp_last[0], b->hold[1] = b->sp_last[1], b->rep.apart_events++;
    else nds_world_ee(b->world, b->hold), b->rep.hold_events++;
    changed = 1;
  } else if (b->holding && b->rep.apart && !timely) {
    b->rep.apart = 0;  /* then stale: the commander is gone, the hold stays put */
    b->rep.hold_events++;
    changed = 1;
  }
  if (fresh && silence > BRIDGE_CMD_HORIZON && !b->silent) {
    b->silent = 1;
    b->rep.silent_events++;
  }
  b->sample[1] = b->sample[0];
  bridge_sample *sa = &b->sample[0];
  sa->silence = silence;
  if (b->holding) {
    for (int k = 0; k < 2; k++) {
      sp[k][ND_P] = b->hold[k];
      sp[k][ND_V] = sp[k][ND_A] = sp[k][ND_J] = 0.0;
    }
    sa->how = BRIDGE_SAMPLE_HOLD, sa->h = h, sa->cmd_seq = b->last.seq;
  } else if (h < 0 && b->have_prev && utime >= b->prev.utime) {
    sa->h = (double)(utime - b->prev.utime) * 1e-6;
    sa->how = BRIDGE_SAMPLE_PREV, sa->cmd_seq = b->prev.seq;
    sample(&b->prev, sa->h, sp);
  } else {
    sa->how = h > BRIDGE_CMD_TAYLOR ? BRIDGE_SAMPLE_FUTURE : BRIDGE_SAMPLE_TAYLOR;
    sa->h = h, sa->cmd_seq = b->last.seq;
    sample(&b->last, h, sp);
  }
  join(b, utime, sp);
  for (int k = 0; k < 2; k++) b->sp_last[k] = sp[k][ND_P];
  return changed;
}

/* Encode the arm's joints (ARM_STATE) into the ring. */
static void put_arm(bridge_loop *b, const nds_world_robot *r, int64_t utime) {
  unsigned char *slot = nd_ring_reserve(&b->out);
  if (slot) {
    nudge_arm_state_t a;
    a.utime = utime;
    a.seq = b->arm_seq;
    memcpy(a.q, r->q, sizeof(a.q));
    memcpy(a.dq, r->dq, sizeof(a.dq));
    memcpy(a.tau, r->tau, sizeof(a.tau));
    const int n = nudge_arm_state_t_encode(slot, 0, ND_RTIO_MAX, &a);
    if (n > 0) nd_ring_commit(&b->out, BRIDGE_TAG_ARM_STATE, n);
    b->rep.arm_states++;
  }
  b->arm_seq++;
}

/* The newest PLACE, applied once the sphere and this step's setpoint sp are at rest and
 * the sphere is its clear from the pose, or dropped after NUDGE_PLACE_T_WAIT. 1 when the
 * report has news. */
static int place(bridge_loop *b, double now, const double sp[2][4]) {
  bridge_place pl;
  if (nd_mailbox_take(&b->place, &b->pl_version, &pl, sizeof(pl)) == (int)sizeof(pl))
    b->pl = pl, b->pl_pending = 1;
  if (!b->pl_pending) return 0;
  const int rest = b->ee_speed < BRIDGE_PLACE_REST &&
                   hypot(sp[0][ND_V], sp[1][ND_V]) < BRIDGE_PLACE_REST;
  if (!rest && now - b->pl.arrival < NUDGE_PLACE_T_WAIT) return 0;
  const double *p = b->pl.pose;
  /* Not at rest: only the gap, for the report (an infinite clear places nothing). */
  const double gap = nds_world_place(b->world, p[0], p[1], p[2], rest ? b->pl.clear : INFINITY);
  const int placed = gap >= b->pl.clear && rest;
  if (!placed && now - b->pl.arrival < NUDGE_PLACE_T_WAIT) return 0;
  b->pl_pending = 0;
  if (placed) b->rep.places++;
  else b->rep.places_dropped++;
  b->rep.place_id = b->pl.id;
  memcpy(b->rep.place_pose, p, sizeof(b->rep.place_pose));
  b->rep.place_gap = gap;
  return 1;
}

void bridge_loop_step(bridge_loop *b, double now, int64_t utime) {
  double sp[2][4];
  int post = setpoint(b, now, utime, sp);
  post |= place(b, now, sp);
  const uint64_t req = atomic_load_explicit(&b->resume_req, memory_order_relaxed);
  if (req != b->resume_seen) {  /* a new task or PLACE: a stopped arm tracks again */
    b->resume_seen = req;
    nds_world_resume(b->world);
  }
  nds_world_out out;
  nds_world_step(b->world, sp, &out);
  if (out.reset) {
    b->rep.resets++;
    if (b->holding) nds_world_ee(b->world, b->hold);
  }
  b->ee_speed = hypot(out.robot.ee_vel[0], out.robot.ee_vel[1]);
  if (out.robot.stopped != b->rep.stopped) {
    b->rep.stopped = out.robot.stopped;
    b->rep.stops += out.stopped_now;
    if (out.stopped_now) {
      b->rep.reflex = out.robot.reflex;
      memcpy(b->rep.stop_sample, b->sample, sizeof(b->sample));
    }
    post = 1;
  }

  unsigned char *slot = b->quiet ? NULL : nd_ring_reserve(&b->out);
  if (slot) {
    nudge_robot_state_t rs;
    memset(&rs, 0, sizeof(rs));
    rs.utime = utime;
    rs.seq = b->rs_seq;
    memcpy(rs.ee_pos, out.robot.ee_pos, sizeof(rs.ee_pos));
    memcpy(rs.ee_vel, out.robot.ee_vel, sizeof(rs.ee_vel));
    memcpy(rs.ee_force, out.robot.ee_force, sizeof(rs.ee_force));
    rs.mode = out.robot.stopped ? NUDGE_ROBOT_STATE_T_MODE_STOPPED
              : b->holding      ? NUDGE_ROBOT_STATE_T_MODE_HOLDING
                                : NUDGE_ROBOT_STATE_T_MODE_TRACKING;
    /* nds_panda numbers its reflexes as robot_state_t does; joints 0..6 are 1..7 there. */
    rs.reflex = out.robot.stopped ? (int8_t)out.robot.reflex.kind : 0;
    rs.reflex_joint = out.robot.stopped ? (int8_t)(out.robot.reflex.joint + 1) : 0;
    const int n = nudge_robot_state_t_encode(slot, 0, ND_RTIO_MAX, &rs);
    if (n > 0) nd_ring_commit(&b->out, BRIDGE_TAG_ROBOT_STATE, n);
    b->rep.robot_states++;
  }
  b->rs_seq++;  /* also on a full ring, so receivers see the gap */

  const double t = nds_world_time(b->world);
  for (int i = 0; i < out.nframes; i++) {
    const nds_world_frame *f = &out.frame[i];
    slot = b->quiet ? NULL : nd_ring_reserve(&b->out);
    if (slot) {
      nudge_mocap_t mc;
      memset(&mc, 0, sizeof(mc));
      /* utime is the capture time: a frame's latency shows as its age. */
      mc.utime = utime - (int64_t)((t - f->capture_t) * 1e6 + 0.5);
      mc.seq = f->index;  /* a dropped frame shows as a gap, as a camera's numbering does */
      memcpy(mc.obj_pos, f->obj_pos, sizeof(mc.obj_pos));
      memcpy(mc.obj_quat, f->obj_quat, sizeof(mc.obj_quat));
      memcpy(mc.ee_pos, f->ee_pos, sizeof(mc.ee_pos));
      const int n = nudge_mocap_t_encode(slot, 0, ND_RTIO_MAX, &mc);
      if (n > 0) nd_ring_commit(&b->out, BRIDGE_TAG_MOCAP, n);
      b->rep.frames++;
    }
    b->mc_seq++;
  }
  if (out.robot.arm && b->rep.steps % BRIDGE_LOOP_ARM_STEPS == 0) {
    if (b->quiet) b->arm_seq++;
    else put_arm(b, &out.robot, utime);
  }
  b->rep.unpublished += b->quiet;
  b->rep.steps++;
  if (post || b->rep.steps % BRIDGE_LOOP_REPORT_STEPS == 0) bridge_loop_report_post(b);
}

int bridge_loop_catch_up_max(double rate) {
  return (int)ceil(BRIDGE_CATCH_UP_S * rate);
}

void bridge_loop_tick(void *ctx, const nd_rtloop_tick *t) {
  bridge_loop *b = ctx;
  /* How old this deadline is at the wake-up that serves it. */
  const double late = 1e-6 * (double)(t->wake_utime - t->utime);
  if (late > BRIDGE_STALL_S && b->have_cmd && t->deadline - b->last.arrival <= b->cmd_timeout)
    b->awake_since = t->deadline + late;  /* the commands were timely when the stall began */
  b->quiet = late > BRIDGE_PUBLISH_S;
  bridge_loop_step(b, t->deadline, t->utime);
  b->quiet = 0;
}
