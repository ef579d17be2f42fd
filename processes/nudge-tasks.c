/* nudge-tasks: the episode runner. Publishes one pushing task (TASK) at a time, watches
 * the object on MOCAP, ends the task on the terminal condition (DESIGN.md sec. 4) and
 * reports it on EPISODE and as one line on stdout.
 *
 * The object is not reset between tasks (a real robot cannot do that): each goal starts
 * where the previous task left the object, so the default goals form a chain of short
 * pushes. Times are measured on this host's monotonic clock, from the TASK publication to
 * the arrival of the MOCAP frame that met the condition. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_cost.h"
#include "nd_math.h"
#include "nd_parse.h"
#include "ndp.h"
#include "ndp_goals.h"
#include "ndp_validate.h"

#define PROG "nudge-tasks"
#define MAX_GOALS 1000
#define MOCAP_GAP_WARN 0.5 /* s without a frame during a task before saying so */

/* Start: object at rest at the origin, the bridge's sphere at (-0.10, 0). Each goal is a
 * 14-16 cm push from the previous one, so every task starts with the object near the last
 * goal and a push of about one object length ahead: straight ahead, a diagonal push with a
 * quarter turn, a push sideways onto the long face, a pull back that needs the sphere to go
 * around the object, and a diagonal push back with a turn the other way. All stay well
 * inside the default 0.5 m workspace, so the sphere has room behind the object. */
static const ndp_goal default_goals[] = {
    {0.15, 0.00, 0.0, 0, 0, 0},  {0.25, 0.10, 0.4, 0, 0, 0}, {0.25, 0.25, 0.8, 0, 0, 0},
    {0.10, 0.30, 0.8, 0, 0, 0},  {0.00, 0.20, 0.3, 0, 0, 0},
};

/* What the runner was asked to do; constant once parsed. */
typedef struct {
  double eps, tau;  /* defaults for goals that set none */
  double workspace; /* goals need |x|, |y| <= workspace, m */
  double wait;      /* for the first MOCAP frame, s */
  double settle;    /* between tasks, s */
  const char *url;
  ndp_goal goals[MAX_GOALS];
  int n;
} tasks_cfg;

/* What the LCM handlers update. */
typedef struct {
  nudge_mocap_t last; /* newest valid frame */
  double t_last;      /* its arrival, ndp_mono() */
  int64_t frames;     /* valid frames received */
  int fresh;          /* a valid frame arrived since the runner last looked */
  ndp_status st;
  int64_t refused_logged;
  double log_next;
} tasks_io;

/* How one task ended. */
typedef struct {
  int event;         /* NUDGE_EPISODE_T_EVENT_* */
  int interrupted;   /* ended by SIGINT/SIGTERM */
  double time;       /* s since the task started */
  double task_error;
  double pos_err;    /* m */
  double yaw_err;    /* rad, modulo the cuboid's half-turn, in [0, pi/2] */
  char reason[200];
} task_result;

static volatile sig_atomic_t quit_sig = 0;

static void on_quit(int sig) {
  ndp_quit = 1;
  quit_sig = sig;
}

/* ndp_signals, remembering which signal it was: the exit status reports it (128 + n). */
static void install_signals(void) {
  ndp_signals();
  struct sigaction sa;
  memset(&sa, 0, sizeof(sa));
  sa.sa_handler = on_quit;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
}

static void on_mocap(const lcm_recv_buf_t *rbuf, const char *ch, const nudge_mocap_t *m,
                     void *user) {
  (void)rbuf;
  (void)ch;
  tasks_io *io = user;
  char why[200];
  if (ndp_check_mocap(m, why, sizeof(why))) {
    io->st.rejected++;
    /* The first few reasons, then one every 10 s: a broken publisher must not flood. */
    double now = ndp_mono();
    if (io->refused_logged < 3 || now >= io->log_next) {
      fprintf(stderr, PROG ": refused MOCAP frame (%lld so far): %s\n",
              (long long)io->st.rejected, why);
      io->refused_logged++;
      io->log_next = now + 10.0;
    }
    return;
  }
  io->last = *m;
  io->t_last = ndp_mono();
  io->frames++;
  io->fresh = 1;
  io->st.received++;
}

static double yaw_error(double yaw, double goal_yaw) {
  double e = fabs(nd_wrap_angle(yaw - goal_yaw));
  return e > 0.5 * ND_PI ? ND_PI - e : e;
}

/* Errors of the newest frame against goal g. */
static void measure(const tasks_io *io, const nd_cost_weights *w, const nd_goal *g,
                    task_result *r) {
  const double yaw = nd_quat_yaw(io->last.obj_quat);
  r->task_error = nd_task_error(w, g, io->last.obj_pos, yaw);
  r->pos_err = hypot(io->last.obj_pos[0] - g->x, io->last.obj_pos[1] - g->y);
  r->yaw_err = yaw_error(yaw, g->yaw);
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
static int pump(lcm_t *lcm, tasks_io *io, double dt, char *err, int errlen) {
  if (ndp_handle(lcm, dt) || ndp_status_tick(lcm, &io->st, 0) < 0) {
    snprintf(err, errlen, "LCM failed while receiving or publishing");
    return -1;
  }
  return 0;
}

/* Wait until a valid MOCAP frame arrives, up to wait s. 1 if one did, 0 if not (or
 * interrupted), -1 on an LCM failure. */
static int wait_mocap(lcm_t *lcm, tasks_io *io, double wait, char *err, int errlen) {
  const double t_end = ndp_mono() + wait;
  while (!io->frames && !ndp_quit) {
    const double left = t_end - ndp_mono();
    if (left <= 0.0) return 0;
    if (pump(lcm, io, fmin(left, 0.1), err, errlen)) return -1;
  }
  return io->frames > 0;
}

/* Run goal g as task id: publish it, follow MOCAP to the terminal condition, publish the
 * outcome. 0 with r filled, or -1 with a message on an LCM failure. */
static int run_task(lcm_t *lcm, tasks_io *io, const tasks_cfg *c, const ndp_goal *g,
                    int64_t id, task_result *r, char *err, int errlen) {
  const nd_cost_weights w = nd_cost_weights_default();
  const nd_goal goal = {g->x, g->y, g->yaw};
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
    if (pump(lcm, io, 0.02, err, errlen)) return -1;
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
  if (r->interrupted) {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "interrupted: the runner was stopped at %.2f s",
             r->time);
  } else if (s == ND_TASK_SUCCESS) {
    r->event = NUDGE_EPISODE_T_EVENT_SUCCESS;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g < eps %.3g", r->task_error, eps);
  } else {
    r->event = NUDGE_EPISODE_T_EVENT_TIMEOUT;
    snprintf(r->reason, sizeof(r->reason), "task error %.3g >= eps %.3g after %.2f s%s",
             r->task_error, eps, tau, age > MOCAP_GAP_WARN ? " (MOCAP stale)" : "");
  }
  if (publish_episode(lcm, io, id, r->event, r->reason, r->time, r->task_error)) goto fail;
  return 0;
fail:
  snprintf(err, errlen, "cannot publish on LCM");
  return -1;
}

/* "task 3/5 goal (+0.20, +0.00, +0.0 deg): reached in 2.41 s, pos err ..." */
static void print_result(int i, int n, const ndp_goal *g, const task_result *r) {
  printf("task %d/%d goal (%+.2f, %+.2f, %+.1f deg): ", i + 1, n, g->x, g->y,
         g->yaw * 180.0 / ND_PI);
  if (r->event == NUDGE_EPISODE_T_EVENT_REJECTED) {
    printf("rejected: %s\n", r->reason);
  } else {
    const char *what = r->interrupted ? "interrupted after"
                       : r->event == NUDGE_EPISODE_T_EVENT_SUCCESS ? "reached in"
                                                                   : "timed out after";
    printf("%s %.2f s, pos err %.3f m, yaw err %.1f deg\n", what, r->time, r->pos_err,
           r->yaw_err * 180.0 / ND_PI);
  }
  fflush(stdout);
}

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Run pushing tasks one after another: publish each goal on TASK, follow the object\n"
          "on MOCAP until the task error L_pos + l1 L_rot falls below eps (reached) or the\n"
          "time limit passes (timed out), report it on EPISODE and as a line on stdout.\n"
          "The object is not reset between tasks: each starts where the last one ended.\n\n"
          "  --goal X,Y,YAW[,EPS[,TIME_LIMIT]]\n"
          "                      a goal pose (m, m, rad); repeatable, run in order\n"
          "  --goals FILE        goals from FILE, one per line: x y yaw [eps [time_limit]]\n"
          "                      ('#' comments, blank lines ignored); repeatable\n"
          "                      without goals: a chain of 5 pushes of 14-16 cm from the origin\n"
          "  --eps E             success threshold, default 1e-2 (per-goal values override)\n"
          "  --tau S             time limit per task, s, default 5 (per-goal values override)\n"
          "  --workspace M       goals beyond |x| or |y| > M are rejected, default 0.5 m\n"
          "  --wait S            wait for the first MOCAP frame, default 10 s\n"
          "  --settle S          pause between tasks so the object comes to rest, default 0.5 s\n"
          "  --lcm-url URL       default $LCM_DEFAULT_URL, else " NDP_DEFAULT_URL "\n"
          "  -h, --help          this text\n\n"
          "Prints one line per task, summary figures as 'name value unit' lines, and ends with\n"
          "'reached K/N goals'. Exit status: 0 every task ran (reached, timed out or rejected),\n"
          "1 the tasks could not be run (no MOCAP, LCM failure), 2 bad arguments,\n"
          "128+n when stopped by signal n (SIGINT: 130), after printing what ran.\n");
}

/* Parse argv into c. 0 to run, 1 for --help, -1 with a message on a bad argument. */
static int parse_args(int argc, char **argv, tasks_cfg *c, char *err, int errlen) {
  c->eps = 1e-2;
  c->tau = 5.0;
  c->workspace = 0.5;
  c->wait = 10.0;
  c->settle = 0.5;
  c->url = NULL;
  c->n = 0;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) return 1;
    int known = !strcmp(a, "--goal") || !strcmp(a, "--goals") || !strcmp(a, "--eps") ||
                !strcmp(a, "--tau") || !strcmp(a, "--workspace") || !strcmp(a, "--wait") ||
                !strcmp(a, "--settle") || !strcmp(a, "--lcm-url");
    if (!known) {
      snprintf(err, errlen, "unknown argument: %s", a);
      return -1;
    }
    if (i + 1 >= argc) {
      snprintf(err, errlen, "%s needs a value", a);
      return -1;
    }
    const char *v = argv[++i];
    int rc = 0;
    if (!strcmp(a, "--goal")) {
      if (c->n >= MAX_GOALS) {
        snprintf(err, errlen, "more than %d goals", MAX_GOALS);
        return -1;
      }
      if ((rc = ndp_goal_parse_arg(v, &c->goals[c->n], err, errlen)) == 0) c->n++;
    } else if (!strcmp(a, "--goals")) {
      const int n0 = c->n;
      rc = ndp_goals_load(v, c->goals, MAX_GOALS, &c->n, err, errlen);
      if (!rc && c->n == n0) {
        snprintf(err, errlen, "%s: no goals in the file", v);
        rc = -1;
      }
    } else if (!strcmp(a, "--eps")) {
      rc = nd_parse_double(v, "--eps", 1e-12, 1.0, &c->eps, err, errlen);
    } else if (!strcmp(a, "--tau")) {
      rc = nd_parse_double(v, "--tau", 1e-3, NDP_GOAL_MAX_TAU, &c->tau, err, errlen);
    } else if (!strcmp(a, "--workspace")) {
      rc = nd_parse_double(v, "--workspace", 1e-3, NDP_GOAL_MAX_POS, &c->workspace, err, errlen);
    } else if (!strcmp(a, "--wait")) {
      rc = nd_parse_double(v, "--wait", 0.0, 3600.0, &c->wait, err, errlen);
    } else if (!strcmp(a, "--settle")) {
      rc = nd_parse_double(v, "--settle", 0.0, 3600.0, &c->settle, err, errlen);
    } else {
      c->url = v;
    }
    if (rc) return -1;
  }
  if (c->n == 0) {
    c->n = (int)(sizeof(default_goals) / sizeof(default_goals[0]));
    memcpy(c->goals, default_goals, sizeof(default_goals));
  }
  return 0;
}

static tasks_cfg cfg; /* static: the goal list is large */

int main(int argc, char **argv) {
  char err[512];
  const int pa = parse_args(argc, argv, &cfg, err, sizeof(err));
  if (pa == 1) {
    usage(stdout);
    return 0;
  }
  if (pa < 0) {
    fprintf(stderr, PROG ": %s\n", err);
    usage(stderr);
    return 2;
  }
  install_signals();

  const char *url = ndp_url(cfg.url);
  lcm_t *lcm = ndp_lcm_create(url, err, sizeof(err));
  if (!lcm) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  static tasks_io io;
  ndp_status_init(&io.st, PROG);
  io.st.state = "waiting";
  nudge_mocap_t_subscription_t *sub = nudge_mocap_t_subscribe(lcm, NDP_CH_MOCAP, on_mocap, &io);
  fprintf(stderr, PROG ": %d goal(s), eps %g, tau %g s, workspace %.2f m, settle %g s, lcm %s\n",
          cfg.n, cfg.eps, cfg.tau, cfg.workspace, cfg.settle, url);

  int status = 1, ran = 0, reached = 0, attempted = 0;
  double t_sum = 0.0, pos_sum = 0.0;
  const int w = wait_mocap(lcm, &io, cfg.wait, err, sizeof(err));
  if (w < 0) {
    fprintf(stderr, PROG ": %s\n", err);
    goto done;
  }
  if (w == 0 && !ndp_quit) {
    fprintf(stderr,
            PROG ": no MOCAP frame within %g s on %s: is nudge-bridge running on the same "
            "LCM URL?\n", cfg.wait, url);
    goto done;
  }

  /* Task ids continue from the wall clock in ms, so a restarted runner never reuses an id
   * a planner may still hold. */
  const int64_t id0 = ndp_utime() / 1000;
  for (int i = 0; i < cfg.n && !ndp_quit; i++) {
    task_result r;
    if (run_task(lcm, &io, &cfg, &cfg.goals[i], id0 + i, &r, err, sizeof(err))) {
      fprintf(stderr, PROG ": %s\n", err);
      goto done;
    }
    print_result(i, cfg.n, &cfg.goals[i], &r);
    if (r.interrupted) break;
    ran++;
    if (r.event != NUDGE_EPISODE_T_EVENT_REJECTED) {
      attempted++;
      pos_sum += r.pos_err;
    }
    if (r.event == NUDGE_EPISODE_T_EVENT_SUCCESS) {
      reached++;
      t_sum += r.time;
    }
    if (i + 1 < cfg.n && r.event != NUDGE_EPISODE_T_EVENT_REJECTED) {
      io.st.state = "settling";
      const double t_end = ndp_mono() + cfg.settle;
      while (!ndp_quit && ndp_mono() < t_end)
        if (pump(lcm, &io, fmin(0.05, t_end - ndp_mono()), err, sizeof(err))) {
          fprintf(stderr, PROG ": %s\n", err);
          goto done;
        }
    }
  }
  io.st.state = "done";
  ndp_status_tick(lcm, &io.st, 1);

  /* name value unit lines for scripts, then the line people read. */
  printf("tasks_run %d count\n", ran);
  printf("tasks_reached %d count\n", reached);
  if (reached) printf("reach_time_mean %.3f s\n", t_sum / reached);
  if (attempted) printf("final_pos_err_mean %.4f m\n", pos_sum / attempted);
  if (ndp_quit)
    printf("reached %d/%d goals (interrupted: %d of %d tasks ran)\n", reached, ran, ran,
           cfg.n);
  else
    printf("reached %d/%d goals\n", reached, ran);
  fflush(stdout);
  status = ndp_quit ? 128 + (quit_sig ? quit_sig : SIGINT) : 0;
done:
  if (status == 1 && ndp_quit) status = 128 + (quit_sig ? quit_sig : SIGINT);
  nudge_mocap_t_unsubscribe(lcm, sub);
  lcm_destroy(lcm);
  return status;
}
