/* plan: one plan from the newest inputs, and the release after a task, published on PLAN
 * (planner.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_cost.h"
#include "nd_exec.h"
#include "nd_math.h"
#include "nd_release.h"
#include "planner.h"

/* The setpoint sp0 the executor starts a plan's first segment from: its newest EE_CMD. No
 * setpoint yet, or the executor has gone quiet: the robot holds where it is. 1 if from
 * EE_CMD. */
static int start_setpoint(const planner_proc *p, double now, double sp0[2][4]) {
  const int cmd_ok = ndp_input_fresh(&p->in_cmd, now, p->o->state_timeout);
  for (int k = 0; k < 2; k++) {
    sp0[k][0] = cmd_ok ? p->cmd.p[k] : p->rs.ee_pos[k];
    sp0[k][1] = cmd_ok ? p->cmd.v[k] : 0.0;
    sp0[k][2] = cmd_ok ? p->cmd.a[k] : 0.0;
    sp0[k][3] = cmd_ok ? p->cmd.j[k] : 0.0;
  }
  return cmd_ok;
}

/* Stamp m with what every PLAN of the task carries (time, id, task, state time, theta) and
 * publish it. Return 0, or -1 with a message. */
static int publish(planner_proc *p, nudge_plan_t *m, char *err, int errlen) {
  m->utime = ndp_utime();
  m->plan_id = ++p->plan_id;
  m->task_id = p->task.task_id;
  m->state_utime = p->mocap.utime;
  m->theta_version = p->theta_version;
  if (nudge_plan_t_publish(p->lcm, NDP_CH_PLAN, m) != 0) {
    snprintf(err, errlen, "publishing on %s failed", NDP_CH_PLAN);
    return -1;
  }
  p->st.published++;
  return 0;
}

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
   * too. */
  double sp0[2][4];
  const int cmd_ok = start_setpoint(p, now, sp0);
  const nd_goal goal = {.x = p->task.goal_x, .y = p->task.goal_y, .yaw = p->task.goal_yaw,
                        .eps = p->task.eps};
  if (!p->edge_warned) {
    const nds_planner_cfg *pc = nds_planner_config(p->planner);
    nd_cost_weights box = pc->w;
    box.prox_lead = 0.0; /* L_edge of the box itself */
    const double e = sqrt(nd_cost_edge(&box, &goal, s.obj_pos, pc->ws_lo, pc->ws_hi));
    if (e > PLANNER_EDGE_WARN) {
      fprintf(stderr, PROG ": task %lld: the object at (%+.3f, %+.3f) m lies %.3f m outside the "
              "keypoint box x [%g, %g] y [%g, %g] m: the sphere cannot get behind it to push it "
              "back\n", (long long)p->task.task_id, s.obj_pos[0], s.obj_pos[1], e,
              pc->ws_lo[0], pc->ws_hi[0], pc->ws_lo[1], pc->ws_hi[1]);
      p->edge_warned = 1;
    }
  }

  double t0 = ndp_mono();
  int64_t start_utime = 0;
  char why[160];
  nds_state s1;
  if (o->lead && cmd_ok) {
    /* Plan from where the world will be when the plan starts: the object and sphere from
     * the state's capture time, the sphere tracking what the executor has committed to,
     * up to the moment the executor will have this plan. */
    const double dt = o->plan_dt;
    const int64_t now_utime = ndp_utime(), t_state = p->mocap.utime;
    const double ahead = 1e-6 * (double)(now_utime - t_state) + p->plan_s * PLANNER_LEAD_GAIN +
                         PLANNER_LEAD_MARGIN;
    int n = (int)ceil(ahead / dt);
    if (n < 0) n = 0;
    if (n > PLANNER_PRE_MAX) n = PLANNER_PRE_MAX;
    nd_exec_future f;
    const double tc = 1e-6 * (double)(p->cmd.utime - t_state);
    f.t_seg_end = 1e-6 * (double)(p->cmd.seg_end_utime - t_state);
    f.t_brake = 1e-6 * (double)(p->cmd.brake_utime - t_state);
    f.t_rest = 1e-6 * (double)(p->cmd.rest_utime - t_state);
    memcpy(f.key, p->cmd.seg_key, sizeof(f.key));
    memcpy(f.hold, p->cmd.hold, sizeof(f.hold));
    /* Times on the state's clock (0 = its capture); before the command's, its setpoint. */
    for (int i = 0; i < n; i++)
      nd_exec_future_eval((const double(*)[4])sp0, tc, &f, i * dt, p->pre_sp[i]);
    nd_exec_future_eval((const double(*)[4])sp0, tc, &f, n * dt, sp0);
    if (nds_planner_predict(p->planner, &s, (const double(*)[2][4])p->pre_sp, n, &s1, why,
                            sizeof(why))) {
      planner_reject(p, "plan input", why);
      return 0;
    }
    s = s1;
    start_utime = t_state + (int64_t)llround(1e6 * n * dt);
    p->lead_sum += n * dt;
  }

  /* The warm start goes on along the last plan to where this one starts (a task's first
   * plan has none to move). */
  const int64_t t_start = start_utime ? start_utime : ndp_utime();
  nds_planner_retime(p->planner, 1e-6 * (double)(t_start - p->last_start_utime));
  p->last_start_utime = t_start;

  nds_plan plan;
  if (nds_planner_plan(p->planner, &s, (const double(*)[4])sp0, &goal, &plan, why,
                       sizeof(why))) {
    /* Inputs are validated, so this is a non-finite estimate: skip this round. */
    planner_reject(p, "plan input", why);
    return 0;
  }
  double ms = 1e3 * (ndp_mono() - t0);
  /* The lead follows the plan time over the last ~5 plans. */
  p->plan_s = p->plan_s > 0.0 ? 0.8 * p->plan_s + 0.2e-3 * ms : 1e-3 * ms;

  nudge_plan_t m;
  memset(&m, 0, sizeof(m));
  m.start_utime = start_utime;
  m.start_p[0] = sp0[0][0];
  m.start_p[1] = sp0[1][0];
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
  if (publish(p, &m, err, errlen)) return -1;
  p->task_plans++;
  p->task_ms_sum += ms;
  p->task_evals += plan.evals;
  p->task_over_limits += plan.over_limits;
  p->task_over_arm += plan.over_arm;
  p->task_rollouts += plan.rollouts;
  p->task_redrawn += plan.redrawn;
  if (ms > p->task_ms_max) p->task_ms_max = ms;
  return 0;
}

/* 1 if MOCAP and ROBOT_STATE are fresh enough to place a release by. */
static int release_sensed(const planner_proc *p, double now) {
  return ndp_input_fresh(&p->in_mocap, now, p->o->state_timeout) &&
         ndp_input_fresh(&p->in_rs, now, p->o->state_timeout);
}

/* 1 while a PLACE's object is not yet seen at its pose (PLANNER_PLACE_*). */
static int placing(planner_proc *p, double now) {
  if (!p->place_pending) return 0;
  const double dx = p->mocap.obj_pos[0] - p->place.x, dy = p->mocap.obj_pos[1] - p->place.y;
  if (now - p->place_at > NUDGE_PLACE_T_WAIT ||
      (p->mocap.utime > p->place.utime && hypot(dx, dy) < PLANNER_PLACE_AT))
    p->place_pending = 0;
  return p->place_pending;
}

/* The object as nd_release sees it: its newest MOCAP pose and the model's sides, or the
 * pose a PLACE puts it at until it is seen there. */
static nd_release_box release_box(planner_proc *p, double now) {
  if (placing(p, now))
    return (nd_release_box){.x = p->place.x, .y = p->place.y, .yaw = p->place.yaw,
                            .half = {p->obj_half[0], p->obj_half[1]}};
  return (nd_release_box){.x = p->mocap.obj_pos[0], .y = p->mocap.obj_pos[1],
                          .yaw = nd_quat_yaw(p->mocap.obj_quat),
                          .half = {p->obj_half[0], p->obj_half[1]}};
}

/* How clear of the object the sphere rests (m): --release, and beyond a PLACE's clear. */
static double release_clear(planner_proc *p, double now) {
  const double c = p->o->release;
  return placing(p, now) ? fmax(c, p->place.clear + PLANNER_PLACE_EXTRA) : c;
}

/* The rest point key[2] release_clear of b from the sphere at from[2], in the keypoint
 * box; return how far it moves the sphere (m). */
static double release_key(planner_proc *p, double now, const nd_release_box *b,
                          const double from[2], double key[2]) {
  const nds_planner_cfg *pc = nds_planner_config(p->planner);
  return nd_release_target(b, p->ee_radius, release_clear(p, now), from, pc->ws_lo, pc->ws_hi,
                           key);
}

/* Publish the PLAN that rests the sphere at key[2] (the object b predicted to stay); renew:
 * the one before re-sent, its segment's end unchanged. */
static int publish_release(planner_proc *p, double now, const nd_release_box *b,
                           const double key[2], int renew, char *err, int errlen) {
  double sp0[2][4];
  start_setpoint(p, now, sp0);
  nudge_plan_t m;
  memset(&m, 0, sizeof(m));
  m.start_p[0] = sp0[0][0];
  m.start_p[1] = sp0[1][0];
  m.M = 1;
  m.keypoints[0][0] = key[0];
  m.keypoints[0][1] = key[1];
  /* As quick as the planner's limits and the arm's joints allow: the executor would only
   * stretch it to its own Cartesian limits, which across the lab's arm exceed the joints'. */
  m.T = nds_planner_rest_time(p->planner, (const double(*)[4])sp0, key, PLANNER_RELEASE_T);
  if (m.T < 0.0) m.T = PLANNER_RELEASE_T;
  m.predicted[0] = b->x;
  m.predicted[1] = b->y;
  m.predicted[2] = b->yaw;
  if (publish(p, &m, err, errlen)) return -1;
  p->released_at = now;
  if (!renew) {
    p->release_until = now + m.T;
    memcpy(p->release_key, key, sizeof(p->release_key));
  }
  return 0;
}

int planner_release(planner_proc *p, double now, char *err, int errlen) {
  const planner_opts *o = p->o;
  if (!release_sensed(p, now)) return 0;
  p->release_due = 0;
  const nd_release_box b = release_box(p, now);
  double key[2];
  const double moved = release_key(p, now, &b, p->rs.ee_pos, key);
  if (publish_release(p, now, &b, key, 0, err, errlen)) return -1;
  p->keep_clear = o->release > 0.0;
  fprintf(stderr, PROG ": task %lld: released: the sphere rests at (%+.3f, %+.3f) m, %.1f mm "
          "out, at least %g m clear of the object\n", (long long)p->task.task_id, key[0], key[1],
          1e3 * moved, o->release);
  return 0;
}

/* The way round the object to the park point, from the sphere: p->park_way. Return NULL,
 * or why there is none. */
static const char *park_plan(planner_proc *p, const nd_release_box *b) {
  const nds_planner_cfg *pc = nds_planner_config(p->planner);
  const double grow = PLANNER_PARK_EXTRA;
  const nd_cost_round r = {{b->half[0] + grow, b->half[1] + grow}, p->ee_radius,
                           {pc->ws_lo[0], pc->ws_lo[1]}, {pc->ws_hi[0], pc->ws_hi[1]}};
  const double box[3] = {b->x, b->y, b->yaw}, park[2] = {p->place.park_x, p->place.park_y};
  if (park[0] < r.lo[0] || park[0] > r.hi[0] || park[1] < r.lo[1] || park[1] > r.hi[1])
    return "it is outside the keypoint box";
  const double *at = p->rs.ee_pos;
  for (p->park_n = 0; p->park_n < PLANNER_PARK_LEGS; p->park_n++) {
    double *next = p->park_way[p->park_n];
    if (nd_cost_round_next(&r, box, at, park, next) < 0.0)
      return "no way round the object within the keypoint box";
    at = next;
    if (nd_dist2(at, park) == 0.0) {
      p->park_n++;
      return NULL;
    }
  }
  return "the way has too many corners";
}

/* The park's next move, once the object is seen at the PLACE's pose and the last move has
 * ended: the way is found at the first; a move whose end the sphere has not reached is
 * sent again (PLANNER_PARK_AT); the park ends with the sphere at the park point. */
static int park_step(planner_proc *p, double now, char *err, int errlen) {
  if (placing(p, now) || !release_sensed(p, now)) return 0;
  const nd_release_box b = release_box(p, now);
  if (p->park_next == 0) {
    const char *why = park_plan(p, &b);
    if (why) {
      p->parking = 0;
      fprintf(stderr, PROG ": PLACE %lld: the sphere does not park at (%+.3f, %+.3f) m from "
              "(%+.3f, %+.3f) m, the object at (%+.3f, %+.3f) m, yaw %+.1f deg: %s\n",
              (long long)p->place.place_id, p->place.park_x, p->place.park_y, p->rs.ee_pos[0],
              p->rs.ee_pos[1], b.x, b.y, b.yaw * 180.0 / ND_PI, why);
      return 0;
    }
    char way[PLANNER_PARK_LEGS * 20] = "";
    for (int k = 0, n = 0; k < p->park_n && n < (int)sizeof(way); k++)
      n += snprintf(way + n, sizeof(way) - (size_t)n, " (%+.3f, %+.3f)", p->park_way[k][0],
                    p->park_way[k][1]);
    fprintf(stderr, PROG ": PLACE %lld: the sphere parks at (%+.3f, %+.3f) m, round the object "
            "at (%+.3f, %+.3f) m in %d move(s):%s\n", (long long)p->place.place_id,
            p->place.park_x, p->place.park_y, b.x, b.y, p->park_n, way);
  }
  if (p->park_next > 0) {
    const double *key = p->park_way[p->park_next - 1];
    const double off = nd_dist2(p->rs.ee_pos, key);
    if (off >= PLANNER_PARK_AT && p->park_tries >= PLANNER_PARK_TRIES) {
      p->parking = 0;
      fprintf(stderr, PROG ": PLACE %lld: the sphere does not park: it stays %.1f mm from "
              "(%+.3f, %+.3f) m after %d moves there\n", (long long)p->place.place_id,
              1e3 * off, key[0], key[1], p->park_tries);
      return 0;
    }
    if (off >= PLANNER_PARK_AT) {
      p->park_tries++;
      return publish_release(p, now, &b, key, 0, err, errlen);
    }
    if (p->park_next == p->park_n) {
      p->parking = 0;
      return 0;
    }
  }
  if (publish_release(p, now, &b, p->park_way[p->park_next], 0, err, errlen)) return -1;
  p->park_next++;
  p->park_tries = 1;
  return 0;
}

int planner_keep_clear(planner_proc *p, double now, char *err, int errlen) {
  /* A stopped arm takes no PLAN until a TASK or PLACE resumes it: nothing to renew, and no
   * park move is spent on it. */
  if (p->rs.mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED) return 0;
  if (now < p->release_until) {
    if (now - p->released_at < PLANNER_RELEASE_RENEW || !release_sensed(p, now)) return 0;
    const nd_release_box b = release_box(p, now);
    return publish_release(p, now, &b, p->release_key, 1, err, errlen);
  }
  if (p->parking) return park_step(p, now, err, errlen);
  if (!p->keep_clear || now - p->released_at < PLANNER_RECLEAR_WAIT || !release_sensed(p, now))
    return 0;
  const nd_release_box b = release_box(p, now);
  double n[2];
  const double gap = nd_release_gap(&b, p->ee_radius, p->rs.ee_pos, n);
  if (gap >= PLANNER_RECLEAR * release_clear(p, now)) return 0;
  double key[2];
  const double moved = release_key(p, now, &b, p->rs.ee_pos, key);
  if (moved < PLANNER_RECLEAR_MIN) {
    p->keep_clear = 0;
    fprintf(stderr, PROG ": task %lld: the object is %.1f mm from the sphere, which the keypoint "
            "box keeps from moving clear: left where it is\n", (long long)p->task.task_id,
            1e3 * gap);
    return 0;
  }
  if (publish_release(p, now, &b, key, 0, err, errlen)) return -1;
  fprintf(stderr, PROG ": task %lld: the object came within %.1f mm of the sphere after the "
          "release: sent clear again, to (%+.3f, %+.3f) m, %.1f mm out\n",
          (long long)p->task.task_id, 1e3 * gap, key[0], key[1], 1e3 * moved);
  return 0;
}

int planner_place(planner_proc *p, double now, char *err, int errlen) {
  if (!release_sensed(p, now)) return 0;
  p->place_due = 0;
  const nd_release_box b = release_box(p, now);
  /* A release on its way rests the sphere at its key, not where it is now, and a key clear
   * of the object's old pose may lie in the placed one: the rest point is found from there,
   * one move rather than a move and a re-clear. One sent before the arm stopped on a
   * reflex is not on its way: the arm rests where the reflex braked it. */
  const int in_flight = now < p->release_until && p->released_at > p->stopped_at;
  const double *from = in_flight ? p->release_key : p->rs.ee_pos;
  double key[2];
  const double moved = release_key(p, now, &b, from, key);
  if (moved > 0.0 && publish_release(p, now, &b, key, 0, err, errlen)) return -1;
  p->keep_clear = 1;
  fprintf(stderr, PROG ": PLACE %lld at (%+.3f, %+.3f) m: the sphere %s (%+.3f, %+.3f) m, %.1f "
          "mm out, at least %g m clear of it\n", (long long)p->place.place_id, b.x, b.y,
          moved > 0.0 || in_flight ? "rests at" : "stays at", key[0], key[1],
          1e3 * moved, release_clear(p, now));
  return 0;
}
