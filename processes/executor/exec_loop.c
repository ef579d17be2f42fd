/* exec_loop: one cycle of the executor's loop (contract in exec_loop.h). */
#include "exec_loop.h"

#include <math.h>
#include <string.h>

#include "nudge/nudge_ee_cmd_t.h"

void exec_loop_io_init(exec_loop_io *io) {
  nd_mailbox_init(&io->state);
  nd_mailbox_init(&io->plan);
  nd_mailbox_init(&io->report);
  nd_ring_init(&io->ring);
}

void exec_loop_init(exec_loop *s, const nd_exec_cfg *cfg, double timeout, double plan_timeout,
                       exec_loop_io *io) {
  memset(s, 0, sizeof(*s));
  s->cfg = *cfg;
  s->timeout = timeout;
  s->plan_timeout = plan_timeout;
  s->io = io;
  s->rep.mode = -1;
  s->rep.plan_id = -1;
  s->rep.refused_id = -1;
  /* lcm-gen computes a type's hash lazily on first use: do it here, not in the loop. */
  (void)nudge_ee_cmd_t_encoded_size(&(nudge_ee_cmd_t){0});
}

void exec_loop_report_post(exec_loop *s, double now, int force) {
  if (!force && now < s->next_report) return;
  s->next_report = now + EXEC_LOOP_REPORT_PERIOD;
  nd_mailbox_post(&s->io->report, &s->rep, (int)sizeof(s->rep));
}

int exec_loop_cycle(exec_loop *s, double now, int64_t utime) {
  const double timeout = s->timeout;
  int dirty = 0;
  exec_loop_state_in st;
  exec_loop_plan_in pl;
  s->rep.cycles++;

  if (nd_mailbox_take(&s->io->state, &s->v_state, &st, (int)sizeof(st)) == (int)sizeof(st)) {
    if (!s->have_state) {
      /* Nothing to command before we know where the robot is: start at rest there. */
      nd_exec_init(&s->ex, st.ee_pos, now);
      s->z = st.ee_pos[2];
      s->have_state = 1;
      dirty = 1;
    }
    s->t_state = st.t_arrive;
    /* A stopped robot brakes its joints back to where the reflex read them, and that
     * reading is the first stopped state's sphere: the setpoint is put there once and stays
     * until the next task or PLACE resumes the robot, whatever the brake's overshoot. The
     * loop hears of a resume a cycle late, so any step in a stopped robot's setpoint can
     * reach it resumed: a Cartesian reflex (0.5 mm in a cycle reads as 500 m/s^2). No
     * plan is followed until a fresh one. */
    if (st.stopped && !s->stopped) nd_exec_init(&s->ex, st.ee_pos, now);
    if (st.stopped) s->have_plan = 0, s->pending = 0;
    s->stopped = st.stopped;
  }
  if (nd_mailbox_take(&s->io->plan, &s->v_plan, &pl, (int)sizeof(pl)) == (int)sizeof(pl)) {
    s->plan = pl;
    s->pending = 1;
  }
  if (!s->have_state) {
    exec_loop_report_post(s, now, dirty);
    return 0;
  }

  const int state_stale = now - s->t_state > timeout;
  /* A plan waits while the state is stale (it would be dropped again at once) and is
   * applied when the state returns, if it is still fresh itself. */
  if (s->pending && !state_stale && !s->stopped && now >= s->plan.t_start) {
    s->pending = 0;
    if (now - s->plan.t_arrive <= s->plan_timeout) {
      /* Restarting the segment for a re-sent keypoint would postpone it by a re-planning
       * period every time, and a planner that keeps re-sending one plan (its search finds
       * nothing better, the robot at rest) would hold the robot still for good: the first
       * 50 ms of a segment that has to arrive fast may go nowhere, and the next plan
       * starts it again from there. So the segment goes on, and the plan only renews it. */
      const double *key = s->plan.keys[0];
      int m = s->plan.M;
      if (m < 1) m = 1;
      if (m > ND_MAX_KEYS) m = ND_MAX_KEYS;
      /* Every keypoint, not only the one followed: a plan heading out of the workspace
       * comes from a planner that does not keep to it (misconfigured, or not ours). */
      int rc = nd_exec_keys_check(&s->cfg, (const double(*)[4])s->plan.keys, m,
                                  s->rep.refused_why, (int)sizeof(s->rep.refused_why));
      const int same =
          rc == ND_EXEC_OK && nd_exec_heading_to(&s->ex, now, key, ND_EXEC_SAME_KEY);
      if (rc == ND_EXEC_OK && !same)
        rc = nd_exec_plan(&s->ex, &s->cfg, now, key, s->plan.T, s->rep.refused_why,
                          (int)sizeof(s->rep.refused_why));
      if (rc == ND_EXEC_OK) {
        double cur[2][4];
        nd_exec_eval(&s->ex, now, cur);
        const double e = hypot(cur[0][ND_P] - s->plan.start_p[0], cur[1][ND_P] - s->plan.start_p[1]);
        s->rep.start_err_sum += e;
        if (e > s->rep.start_err_max) s->rep.start_err_max = e;
        s->have_plan = 1;
        s->t_plan = s->plan.t_arrive;
        s->rep.plan_id = s->plan.plan_id;
        s->rep.plan_utime = s->plan.utime;
        s->rep.accepted++;
        s->rep.kept += same;
      } else {
        /* A refused plan does not refresh the plan clock: a planner sending only
         * unreachable plans must not keep the robot on its old segment. */
        s->rep.refused++;
        s->rep.refused_box += rc == ND_EXEC_EBOX;
        s->rep.refused_id = s->plan.plan_id;
        s->rep.refused_rc = rc;
        dirty = 1;
      }
    } else {
      s->rep.late++;
    }
  }

  int stale = state_stale ? EXEC_STALE_STATE : 0;
  if (!s->have_plan) stale |= EXEC_STALE_NO_PLAN;
  else if (now - s->t_plan > s->plan_timeout) stale |= EXEC_STALE_PLAN;
  if (!stale != !s->rep.stale || s->rep.mode < 0) {
    if (stale) s->rep.n_stale++;
    else s->rep.n_resume++;
    dirty = 1;
  }
  s->rep.stale = stale;

  double sp[2][4];
  const int mode = nd_exec_step(&s->ex, &s->cfg, now, stale != 0, sp);
  if (mode != s->rep.mode) dirty = 1;
  s->rep.mode = mode;

  nudge_ee_cmd_t m;
  m.utime = utime;
  m.seq = s->seq++;
  m.plan_id = s->rep.plan_id;
  m.plan_utime = s->rep.plan_utime;
  m.mode = (int8_t)mode;
  for (int ax = 0; ax < 2; ax++) {
    m.p[ax] = sp[ax][ND_P];
    m.v[ax] = sp[ax][ND_V];
    m.a[ax] = sp[ax][ND_A];
    m.j[ax] = sp[ax][ND_J];
  }
  m.p[2] = s->z;
  m.v[2] = m.a[2] = m.j[2] = 0.0;
  /* The future on the wall clock of utime: now is utime. */
  nd_exec_future f;
  nd_exec_future_get(&s->ex, &f);
  m.seg_end_utime = utime + (int64_t)llround(1e6 * (f.t_seg_end - now));
  m.brake_utime = utime + (int64_t)llround(1e6 * (f.t_brake - now));
  m.rest_utime = utime + (int64_t)llround(1e6 * (f.t_rest - now));
  memcpy(m.seg_key, f.key, sizeof(m.seg_key));
  memcpy(m.hold, f.hold, sizeof(m.hold));

  int ret = -1;
  unsigned char *slot = nd_ring_reserve(&s->io->ring);
  if (slot) {
    /* A fixed-size type: encoding writes into the slot and allocates nothing. */
    const int len = nudge_ee_cmd_t_encode(slot, 0, ND_RTIO_MAX, &m);
    if (len > 0) {
      nd_ring_commit(&s->io->ring, EXEC_LOOP_TAG_EE_CMD, len);
      s->rep.sent++;
      ret = 1;
    }
  }
  exec_loop_report_post(s, now, dirty);
  return ret;
}
