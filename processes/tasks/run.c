/* run: one task, from TASK to EPISODE, and what happens between tasks (tasks.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_cost.h"
#include "nd_math.h"
#include "tasks.h"

static double yaw_error(double yaw, double goal_yaw) {
  double e = fabs(nd_wrap_angle(yaw - goal_yaw));
  return e > 0.5 * ND_PI ? ND_PI - e : e;
}

/* The newest frame's position (m) and yaw (rad) errors against pose g. */
static void pose_error(const tasks_io *io, const nd_goal *g, double *pos, double *yaw) {
  *pos = hypot(io->last.obj_pos[0] - g->x, io->last.obj_pos[1] - g->y);
  *yaw = yaw_error(nd_quat_yaw(io->last.obj_quat), g->yaw);
}

/* Errors of the newest frame against goal g. */
static void measure(const tasks_io *io, const nd_cost_weights *w, const nd_goal *g,
                    tasks_result *r) {
  r->task_error = nd_task_error(w, g, io->last.obj_pos, nd_quat_yaw(io->last.obj_quat));
  pose_error(io, g, &r->pos_err, &r->yaw_err);
}

static int publish_episode(lcm_t *lcm, tasks_io *io, int64_t task_id, int event,
                           const char *reason, double time, double task_error) {
  nudge_episode_t e;
  memset(&e, 0, sizeof(e));
  e.utime = ndp_utime();
  e.task_id = task_id;
  e.event = (int8_t)event;
  e.reason = (char *)reason;
  e.time = time;
  e.task_error = task_error;
  if (nudge_episode_t_publish(lcm, NDP_CH_EPISODE, &e) != 0) return -1;
  io->st.published++;
  return 0;
}

/* Handle LCM and the heartbeat for up to dt seconds. 0, or -1 with a message. */
int tasks_pump(lcm_t *lcm, tasks_io *io, double dt, char *err, int errlen) {
  if (ndp_handle(lcm, dt) || ndp_status_tick(lcm, &io->st, 0) < 0) {
    snprintf(err, errlen, "LCM failed while receiving or publishing");
    return -1;
  }
  return 0;
}

/* Wait until a valid MOCAP frame arrives (and, when recording, a ROBOT_STATE: the first
 * task's start state needs one), up to wait s. 1 if they did, 0 if not (or interrupted),
 * -1 on an LCM failure. */
int tasks_wait_mocap(lcm_t *lcm, tasks_io *io, double wait, char *err, int errlen) {
  const double t_end = ndp_mono() + wait;
  /* MOCAP alone would do for a runner started long after the bridge, but one started (or
   * restarted) while both streams flow may see a MOCAP frame first and would begin its
   * first task without a start state: that task would not be recorded. */
  while ((!io->frames || (io->buf && !io->buf->have_rs)) && !ndp_quit) {
    const double left = t_end - ndp_mono();
    if (left <= 0.0) return 0;
    if (tasks_pump(lcm, io, fmin(left, 0.1), err, errlen)) return -1;
  }
  return io->frames > 0 && (!io->buf || io->buf->have_rs);
}

const char *tasks_reflex_name(int reflex, int joint) {
  static char buf[64];
  static const char *what[] = {"none", "position", "velocity", "acceleration", "torque",
                               "Cartesian velocity", "Cartesian acceleration", "Cartesian jerk",
                               "non-finite reading"};
  const char *w = reflex >= 0 && reflex < (int)(sizeof(what) / sizeof(what[0])) ? what[reflex] : "?";
  if (reflex >= NUDGE_ROBOT_STATE_T_REFLEX_CART_VELOCITY || joint < 1) snprintf(buf, sizeof buf, "%s", w);
  else snprintf(buf, sizeof buf, "joint %d %s", joint, w);
  return buf;
}

/* Run goal g as task id: publish it, follow MOCAP to the terminal condition, publish the
 * outcome. 0 with r filled, or -1 with a message on an LCM failure. */
int tasks_run(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, const nd_goal *g, int64_t id,
              tasks_result *r, char *err, int errlen) {
  const nd_cost_weights w = nd_cost_weights_default();
  const nd_goal goal = {.x = g->x, .y = g->y, .yaw = g->yaw};
  const double eps = g->eps > 0.0 ? g->eps : c->eps;
  const double tau = g->tau > 0.0 ? g->tau : c->tau;
  memset(r, 0, sizeof(*r));
  measure(io, &w, &goal, r);

  if (fabs(g->x) > c->workspace || fabs(g->y) > c->workspace) {
    r->event = NUDGE_EPISODE_T_EVENT_REJECTED;
    snprintf(r->reason, sizeof(r->reason),
             "goal (%.3f, %.3f) m is outside the workspace |x|, |y| <= %.2f m", g->x, g->y,
             c->workspace);
    if (publish_episode(lcm, io, id, r->event, r->reason, 0.0, r->task_error)) goto fail;
    return 0;
  }

  nudge_task_t t;
  memset(&t, 0, sizeof(t));
  t.utime = ndp_utime();
  t.task_id = id;
  t.goal_x = g->x;
  t.goal_y = g->y;
  t.goal_yaw = g->yaw;
  t.eps = eps;
  t.time_limit = tau;
  t.v_max = c->v_max;
  /* A goal met where the object lies is reached at once: its record would hold no push,
   * and a refit on it has nothing to learn from but may still move theta. */
  r->met_at_start = nd_task_check(r->task_error, 0.0, eps, tau) == ND_TASK_SUCCESS;
  if (r->met_at_start && io->buf)
    fprintf(stderr, PROG ": task %lld not recorded: its goal is met at the start (task error "
            "%.3g < eps %.3g), nothing to push\n", (long long)id, r->task_error, eps);
  if (io->buf && !io->no_record && !r->met_at_start)
    tasks_buffer_begin(io->buf, &io->last, id, &goal);
  memset(&io->run, 0, sizeof(io->run));
  io->run.id = id;
  io->run.start = io->last;
  const double t0 = ndp_mono();
  if (nudge_task_t_publish(lcm, NDP_CH_TASK, &t) != 0) goto fail;
  io->st.published++;
  if (publish_episode(lcm, io, id, NUDGE_EPISODE_T_EVENT_START, "", 0.0, r->task_error))
    goto fail;
  io->st.state = "running";
  io->fresh = 0;

  double next_task = t0 + 1.0;
  int gap_warned = 0;
  nd_task_status s = ND_TASK_RUNNING;
  for (;;) {
    if (tasks_pump(lcm, io, 0.02, err, errlen)) return -1;
    const double now = ndp_mono();
    if (ndp_quit) {
      r->interrupted = 1;
      r->time = now - t0;
      break;
    }
    if (io->fresh) {
      io->fresh = 0;
      measure(io, &w, &goal, r);
      r->time = io->t_last - t0;
      s = nd_task_check(r->task_error, r->time, eps, tau);
      gap_warned = 0;
    }
    /* The limit holds even when frames stop coming: judge the last frame at the clock. */
    if (s == ND_TASK_RUNNING && now - t0 > tau) {
      r->time = now - t0;
      s = ND_TASK_TIMEOUT;
    }
    if (s != ND_TASK_RUNNING) break;
    if (io->run.stopped) {
      r->time = now - t0;
      break;
    }
    if (!gap_warned && now - io->t_last > MOCAP_GAP_WARN) {
      fprintf(stderr, PROG ": no MOCAP frame for %.1f s during task %lld\n", now - io->t_last,
              (long long)id);
      gap_warned = 1;
    }
    /* Unchanged, so a planner that starts late or restarts picks the task up. */
    if (now >= next_task) {
      if (nudge_task_t_publish(lcm, NDP_CH_TASK, &t) != 0) goto fail;
      io->st.published++;
      next_task += 1.0;
    }
  }

  const double age = ndp_mono() - io->t_last;
  r->plans = io->run.plans;
  r->obj_path = io->run.obj_path;
  r->ee_path = io->run.ee_path;
  r->ee_speed_max = io->run.ee_speed_max;
  r->cmd_speed_max = io->run.cmd_speed_max;
  r->moved_at = io->run.moved ? io->run.moved_at - t0 : -1.0;
  if (r->interrupted) {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "interrupted: the runner was stopped at %.2f s",
             r->time);
  } else if (io->run.stopped && s == ND_TASK_RUNNING) {
    r->event = NUDGE_EPISODE_T_EVENT_STOPPED;
    snprintf(r->reason, sizeof(r->reason), "the robot stopped on a reflex: %s",
             tasks_reflex_name(io->run.reflex, io->run.reflex_joint));
  } else if (s == ND_TASK_SUCCESS) {
    r->event = NUDGE_EPISODE_T_EVENT_SUCCESS;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g < eps %.3g", r->task_error, eps);
  } else {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g >= eps %.3g after %.2f s%s",
             r->task_error, eps, tau, age > MOCAP_GAP_WARN ? " (MOCAP stale)" : "");
  }
  io->run.id = -1;
  if (publish_episode(lcm, io, id, r->event, r->reason, r->time, r->task_error)) goto fail;
  return 0;
fail:
  snprintf(err, errlen, "cannot publish on LCM");
  return -1;
}

/* "task 3/5 goal (+0.20, +0.00, +0.0 deg): reached in 2.41 s, pos err ..." */
void tasks_print(int i, int n, const nd_goal *g, const tasks_result *r) {
  printf("task %d/%d goal (%+.2f, %+.2f, %+.1f deg): ", i + 1, n, g->x, g->y,
         g->yaw * 180.0 / ND_PI);
  if (r->event == NUDGE_EPISODE_T_EVENT_REJECTED) {
    printf("rejected: %s\n", r->reason);
  } else if (r->event == NUDGE_EPISODE_T_EVENT_STOPPED) {
    printf("stopped after %.2f s, pos err %.3f m: %s\n", r->time, r->pos_err, r->reason);
  } else {
    const char *what = r->interrupted ? "interrupted after"
                       : r->event == NUDGE_EPISODE_T_EVENT_SUCCESS ? "reached in"
                                                                   : "timed out after";
    printf("%s %.2f s, pos err %.3f m, yaw err %.1f deg, %lld plans, object path %.3f m, "
           "sphere path %.3f m, sphere top speed %.2f m/s, command top speed %.2f m/s, ", what,
           r->time, r->pos_err, r->yaw_err * 180.0 / ND_PI, (long long)r->plans, r->obj_path,
           r->ee_path, r->ee_speed_max, r->cmd_speed_max);
    if (r->moved_at >= 0.0) printf("object moved at %.2f s\n", r->moved_at);
    else printf("object not moved\n");
  }
  fflush(stdout);
}


/* After a task: with --await-fit, wait for PARAMS fitted on the record just appended (the
 * paper's task -> append -> refit protocol, after the last task too, so a caller's next
 * run starts on the refit; the adapter's count may stay below ours if it refused a record,
 * hence the limit). */
int tasks_pause(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen) {
  tasks_buffer *b = io->buf;
  if (!(c->await_fit > 0 && b && b->last_ok)) return 0;
  io->st.state = "awaiting fit";
  const double t0 = ndp_mono(), t_end = t0 + c->await_fit;
  while (!ndp_quit && ndp_mono() < t_end && b->params_n < b->w.records)
    if (tasks_pump(lcm, io, fmin(0.05, t_end - ndp_mono()), err, errlen)) return -1;
  if (b->params_n >= b->w.records)
    fprintf(stderr, PROG ": PARAMS version %lld (fitted on %d rollouts) after %.2f s\n",
            (long long)b->theta_version, (int)b->params_n, ndp_mono() - t0);
  else if (!ndp_quit)
    fprintf(stderr, PROG ": no PARAMS fitted on %lld rollouts within %g s; going on\n",
            (long long)b->w.records, c->await_fit);
  return 0;
}

double tasks_frame_shift(const nudge_mocap_t *a, const nudge_mocap_t *b) {
  const double d = hypot(a->obj_pos[0] - b->obj_pos[0], a->obj_pos[1] - b->obj_pos[1]);
  const double dyaw = fabs(nd_wrap_angle(nd_quat_yaw(a->obj_quat) - nd_quat_yaw(b->obj_quat)));
  return fmax(d, REST_ARM * dyaw);
}

/* The object's speed between frames a and b (older), its yaw rate counted at REST_ARM. */
static double frame_speed(const nudge_mocap_t *a, const nudge_mocap_t *b) {
  const double dt = 1e-6 * (double)(a->utime - b->utime);
  return dt > 0.0 ? tasks_frame_shift(a, b) / dt : INFINITY;
}

/* 1 if the newest frame shows the object within PLACE_POS and PLACE_YAW of g. */
static int at_pose(const tasks_io *io, const nd_goal *g) {
  double pos, yaw;
  pose_error(io, g, &pos, &yaw);
  return pos < PLACE_POS && yaw < PLACE_YAW;
}

/* 1 if the newest frame shows the sphere within PARK_AT of c->park_xy. */
static int parked(const tasks_io *io, const tasks_cfg *c) {
  return hypot(io->last.ee_pos[0] - c->park_xy[0], io->last.ee_pos[1] - c->park_xy[1]) <
         PARK_AT;
}

/* "the object was moved ... off the placed pose WHEN: placing it again", by the newest frame. */
static void say_moved(const tasks_io *io, const nd_goal *g, const char *when) {
  double pos, yaw;
  pose_error(io, g, &pos, &yaw);
  fprintf(stderr, PROG ": the object was moved %.1f mm and %.3f rad off the placed pose %s: "
          "placing it again\n", 1e3 * pos, yaw, when);
}

/* A new PLACE (a new place_id) in m, sent at once and not yet seen done. */
static void place_anew(nudge_place_t *m, int *seen, double *sent) {
  m->utime = m->place_id = ndp_utime();
  *seen = 0;
  *sent = -INFINITY;
}

/* One PLACE, re-sent until a frame captured after it shows the object there and, with
 * --park, one the sphere parked (an object moved off the pose before then is placed again
 * here; after, tasks_place checks it once settled): 1, or 0 past c->place_wait (or
 * interrupted), -1 with a message on an LCM failure. */
static int place_once(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen) {
  io->st.state = "placing";
  const nd_goal *g = &c->place_pose;
  const int64_t now_us = ndp_utime();
  nudge_place_t m = {now_us, now_us, g->x, g->y, g->yaw, PLACE_CLEAR,
                     (int8_t)c->park, c->park_xy[0], c->park_xy[1]};
  const double t0 = ndp_mono();
  double sent = -INFINITY;
  int said = 0, seen = 0;
  /* Stops so far (no task runs while placing): one from before this PLACE is acknowledged
   * by it, as nudge-bridge resumes the arm on a new PLACE. */
  int acked = io->stops_between;
  while (!ndp_quit) {
    const double now = ndp_mono();
    /* A reflex stop on the way (the sphere parking or moving clear) holds the arm until a
     * new task or PLACE acknowledges it: a new PLACE, once the arm has braked to rest
     * (STOP_REST), whose park the planner starts afresh from where the sphere stopped. */
    if (io->stops_between > acked && io->robot_stopped == 1 &&
        now - io->ee_moving_at >= STOP_REST) {
      fprintf(stderr, PROG ": the stopped arm is at rest: placing again, which resumes it\n");
      place_anew(&m, &seen, &sent);
      acked = io->stops_between;
    }
    /* Seen at the pose, then moved off it before the sphere parked (knocked on a way the
     * planner did not plan, a hand): the park, planned round the pose, cannot end. A new
     * PLACE puts the object back and parks afresh. */
    if (seen && c->park && !at_pose(io, g) && !parked(io, c)) {
      say_moved(io, g, "while the sphere parked");
      place_anew(&m, &seen, &sent);
    }
    if (io->frames > 0 && io->last.utime > m.utime && !seen) seen = at_pose(io, g);
    if (seen && (!c->park || parked(io, c))) return 1;
    if (now - t0 >= c->place_wait) return 0;
    if (!said && now - t0 >= PLACE_SAY) {
      fprintf(stderr, PROG ": waiting for the object at (%g, %g) m, yaw %g rad (PLACE)\n", g->x,
              g->y, g->yaw);
      said = 1;
    }
    if (now - sent >= PLACE_RESEND) {
      if (nudge_place_t_publish(lcm, NDP_CH_PLACE, &m) != 0) {
        snprintf(err, errlen, "publishing on %s failed", NDP_CH_PLACE);
        return -1;
      }
      io->st.published++;
      sent = now;
    }
    if (tasks_pump(lcm, io, 0.02, err, errlen)) return -1;
  }
  return 0;
}

int tasks_place(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen) {
  const nd_goal *g = &c->place_pose;
  double pos = 0.0, yaw = 0.0;
  for (int k = 0; k < PLACE_TRIES; k++) {
    if (k > 0) say_moved(io, g, "before the task");
    const int pl = place_once(lcm, io, c, err, errlen);
    if (pl <= 0) return pl;
    if (tasks_settle(lcm, io, c, err, errlen)) return -1;
    if (ndp_quit || io->no_record || at_pose(io, g)) return 1;
    pose_error(io, g, &pos, &yaw);
  }
  io->no_record = io->buf != NULL;
  fprintf(stderr, PROG ": the object was moved off the placed pose after each of %d "
          "placements (%.1f mm, %.3f rad the last time)%s\n", PLACE_TRIES, 1e3 * pos, yaw,
          io->buf ? ": the next task is not recorded (a record starts at the placed pose)" : "");
  return 1;
}

int tasks_settle(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, char *err, int errlen) {
  io->st.state = "settling";
  io->no_record = 0;
  const double t0 = ndp_mono();
  /* The speed over the span from a reference frame to the first frame REST_SPAN later,
   * which becomes the next reference. */
  nudge_mocap_t ref;
  int have_ref = 0;
  double speed = INFINITY;
  for (;;) {
    if (ndp_quit) return 0;
    const double now = ndp_mono();
    if (io->frames > 0 && !have_ref) {
      ref = io->last;
      have_ref = 1;
    } else if (have_ref && 1e-6 * (double)(io->last.utime - ref.utime) >= REST_SPAN) {
      speed = frame_speed(&io->last, &ref);
      ref = io->last;
    }
    const int held = now - io->cmd_moving_at >= SETTLE_CMD_REST;  /* -inf: none moved it */
    if (now - t0 >= c->settle && speed < REST_SPEED && held) return 0;
    if (now - t0 >= fmax(c->settle, SETTLE_MAX)) break;
    if (tasks_pump(lcm, io, 0.02, err, errlen)) return -1;
  }
  io->no_record = io->buf != NULL;
  const char *why = io->buf ? ": the next task is not recorded (a record starts at rest)" : "";
  if (speed < REST_SPEED)
    fprintf(stderr, PROG ": the commands still move the sphere after %.1f s%s\n",
            ndp_mono() - t0, why);
  else if (isfinite(speed))
    fprintf(stderr, PROG ": the object still moves at %.3f m/s after %.1f s%s\n", speed,
            ndp_mono() - t0, why);
  else
    fprintf(stderr, PROG ": no MOCAP frames %.1f s apart within %.1f s to tell the object is "
            "at rest%s\n", REST_SPAN, ndp_mono() - t0, why);
  return 0;
}
