/* bridge_loop: one step of the bridge (bridge_loop.h). */
#include "bridge_loop.h"

#include <string.h>

#include "nd_snap.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_robot_state_t.h"

void bridge_loop_init(bridge_loop *b, nds_world *w, double cmd_timeout) {
  memset(b, 0, sizeof(*b));
  b->world = w;
  b->cmd_timeout = cmd_timeout;
  nd_mailbox_init(&b->cmd);
  nd_mailbox_init(&b->report);
  nd_ring_init(&b->out);
  b->holding = 1;  /* no command yet: hold the start position */
  nds_world_ee(w, b->hold);
  /* lcm-gen computes a type's hash lazily on first use: do it here, not in the loop. */
  (void)nudge_robot_state_t_encoded_size(&(nudge_robot_state_t){0});
  (void)nudge_mocap_t_encoded_size(&(nudge_mocap_t){0});
  bridge_loop_report_post(b);
}

void bridge_loop_report_post(bridge_loop *b) {
  b->rep.holding = b->holding;
  b->rep.have_cmd = b->have_cmd;
  b->rep.hold_pos[0] = b->hold[0];
  b->rep.hold_pos[1] = b->hold[1];
  nd_mailbox_post(&b->report, &b->rep, sizeof(b->rep));
}

/* The setpoint: the newest command while fresh, else hold where the sphere was when
 * commands went stale. Return 1 if the hold state changed. */
static int setpoint(bridge_loop *b, double now, double sp[2][4]) {
  bridge_cmd c;
  if (nd_mailbox_take(&b->cmd, &b->cmd_version, &c, sizeof(c)) == (int)sizeof(c)) {
    b->last = c;
    b->have_cmd = 1;
  }
  const int fresh = b->have_cmd && now - b->last.arrival <= b->cmd_timeout;
  int changed = 0;
  if (fresh && b->holding) {
    b->holding = 0;
    changed = 1;
  } else if (!fresh && !b->holding) {
    b->holding = 1;
    nds_world_ee(b->world, b->hold);
    b->rep.hold_events++;
    changed = 1;
  }
  for (int k = 0; k < 2; k++) {
    sp[k][ND_P] = b->holding ? b->hold[k] : b->last.p[k];
    sp[k][ND_V] = b->holding ? 0.0 : b->last.v[k];
    sp[k][ND_A] = b->holding ? 0.0 : b->last.a[k];
    sp[k][ND_J] = 0.0;
  }
  return changed;
}

void bridge_loop_step(bridge_loop *b, double now, int64_t utime) {
  double sp[2][4];
  int post = setpoint(b, now, sp);
  nds_world_out out;
  nds_world_step(b->world, sp, &out);
  if (out.reset) {
    b->rep.resets++;
    if (b->holding) nds_world_ee(b->world, b->hold);
  }

  unsigned char *slot = nd_ring_reserve(&b->out);
  if (slot) {
    nudge_robot_state_t rs;
    memset(&rs, 0, sizeof(rs));
    rs.utime = utime;
    rs.seq = b->rs_seq;
    memcpy(rs.ee_pos, out.robot.ee_pos, sizeof(rs.ee_pos));
    memcpy(rs.ee_vel, out.robot.ee_vel, sizeof(rs.ee_vel));
    memcpy(rs.ee_force, out.robot.ee_force, sizeof(rs.ee_force));
    const int n = nudge_robot_state_t_encode(slot, 0, ND_RTIO_MAX, &rs);
    if (n > 0) nd_ring_commit(&b->out, BRIDGE_TAG_ROBOT_STATE, n);
    b->rep.robot_states++;
  }
  b->rs_seq++;  /* also on a full ring, so receivers see the gap */

  const double t = nds_world_time(b->world);
  for (int i = 0; i < out.nframes; i++) {
    const nds_world_frame *f = &out.frame[i];
    slot = nd_ring_reserve(&b->out);
    if (slot) {
      nudge_mocap_t mc;
      memset(&mc, 0, sizeof(mc));
      /* utime is the capture time: a frame's latency shows as its age. */
      mc.utime = utime - (int64_t)((t - f->capture_t) * 1e6 + 0.5);
      mc.seq = b->mc_seq;
      memcpy(mc.obj_pos, f->obj_pos, sizeof(mc.obj_pos));
      memcpy(mc.obj_quat, f->obj_quat, sizeof(mc.obj_quat));
      memcpy(mc.ee_pos, f->ee_pos, sizeof(mc.ee_pos));
      const int n = nudge_mocap_t_encode(slot, 0, ND_RTIO_MAX, &mc);
      if (n > 0) nd_ring_commit(&b->out, BRIDGE_TAG_MOCAP, n);
      b->rep.frames++;
    }
    b->mc_seq++;
  }
  b->rep.steps++;
  if (post || b->rep.steps % BRIDGE_LOOP_REPORT_STEPS == 0) bridge_loop_report_post(b);
}

void bridge_loop_tick(void *ctx, const nd_rtloop_tick *t) {
  bridge_loop_step(ctx, t->deadline, t->utime);
}
