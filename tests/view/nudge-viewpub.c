/* nudge-viewpub: publishes a scripted sequence of nudge messages for nudge-view's tests, or
 * writes it as an lcm-logger log with LCM's eventlog API (a test helper, not installed).
 *
 *   nudge-viewpub [--lcm-url URL | --log FILE] STEP...
 *
 * Steps, in order (numbers comma-separated, metres, radians, seconds):
 *   at S                      later steps at S s after the start (live: sleeps until then;
 *                             log: the events' timestamps)
 *   mocap X,Y,YAW,EEX,EEY     MOCAP: the box at (X, Y, YAW), the sphere at (EEX, EEY)
 *   task X,Y,YAW,EPS          TASK with the next task id
 *   plan PX,PY,PYAW,T,KX,KY,KVX,KVY[,KX,KY,KVX,KVY...]
 *                             PLAN: predicted pose, segment time, keypoints
 *   cmd X,Y,VX,VY             one EE_CMD setpoint
 *   sweep X0,Y0,X1,Y1,S       EE_CMD at 500 Hz moving from (X0, Y0) to (X1, Y1) over S s,
 *                             with MOCAP at 100 Hz keeping the sphere on the setpoint and
 *                             the box where the last mocap step put it
 *   params S,T,R,M            PARAMS with the next version
 *   status NAME,STATE         a STATUS heartbeat
 *   episode EVENT             EPISODE of the current task (0 start .. 4 stopped)
 *   arm Q1,...,Q7             ARM_STATE
 *   bad-arm                   ARM_STATE messages that must be refused: NaN, inf and
 *                             out-of-range joints, no utime, undecodable bytes
 *                             (nudge-inject has no ARM_STATE); prints
 *                             'inject_ARM_STATE_bad N count' and '..._garbage N count'
 *   bad                       a few messages on each of nudge-view's channels that it
 *                             must refuse (invalid fields, strings it cannot draw, bytes
 *                             that do not decode); prints 'inject_bad N count'
 * Exit status 0, 1 if LCM or the log failed, 2 on a bad step. */
#include <lcm/eventlog.h>
#include <lcm/lcm.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "nd_math.h"
#include "nd_parse.h"
#include "nudge/nudge_arm_state_t.h"
#include "nudge/nudge_ee_cmd_t.h"
#include "nudge/nudge_episode_t.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_params_t.h"
#include "nudge/nudge_plan_t.h"
#include "nudge/nudge_status_t.h"
#include "nudge/nudge_task_t.h"

#define PROG "nudge-viewpub"
#define MAX_MSG 4096
#define EE_Z 0.026  /* the ideal scene's sphere centre height */

typedef struct {
  lcm_t *lcm;
  lcm_eventlog_t *log;
  int64_t t0, t;        /* us: start, and the current step's time */
  int64_t seq, task_id, plan_id, version;
  double box[3];        /* the box's pose of the last mocap step */
  unsigned char buf[MAX_MSG];
  int failed;
} pub;

static int64_t wall_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

/* Live: sleep until the step's time. */
static void wait_for(const pub *p) {
  if (p->log) return;
  for (;;) {
    const int64_t left = p->t - wall_us();
    if (left <= 0) return;
    const struct timespec ts = {left / 1000000, (left % 1000000) * 1000};
    nanosleep(&ts, NULL);
  }
}

static void send(pub *p, const char *ch, int len) {
  if (len < 0) {
    p->failed = 1;
    return;
  }
  if (p->log) {
    lcm_eventlog_event_t e = {0, p->t, (int32_t)strlen(ch), len, (char *)ch, p->buf};
    if (lcm_eventlog_write_event(p->log, &e)) p->failed = 1;
  } else {
    wait_for(p);
    if (lcm_publish(p->lcm, ch, p->buf, len)) p->failed = 1;
  }
}

static void mocap(pub *p, double x, double y, double yaw, double ex, double ey) {
  nudge_mocap_t m = {p->t, ++p->seq, {x, y, 0.025}, {1, 0, 0, 0}, {ex, ey, EE_Z}};
  nd_yaw_quat(yaw, m.obj_quat);
  send(p, "MOCAP", nudge_mocap_t_encode(p->buf, 0, MAX_MSG, &m));
}

static void cmd(pub *p, double x, double y, double vx, double vy) {
  /* Its future: a segment ending here now, no brake (the view draws the trail only). */
  nudge_ee_cmd_t m = {p->t, ++p->seq, p->plan_id, p->plan_id ? p->t : 0, 0, {x, y, EE_Z},
                      {vx, vy, 0}, {0, 0, 0}, {0, 0, 0}, p->t, {x, y, 0, 0}, p->t, p->t,
                      {x, y}};
  send(p, "EE_CMD", nudge_ee_cmd_t_encode(p->buf, 0, MAX_MSG, &m));
}

static void bad_arm(pub *p) {
  const nudge_arm_state_t ok = {p->t, 1, {0}, {0}, {0}};
  nudge_arm_state_t m;
  int nbad = 0, ngarbage = 0;
#define ARM_BAD(stmt)                                                 \
  do {                                                                \
    m = ok;                                                           \
    stmt;                                                             \
    send(p, "ARM_STATE", nudge_arm_state_t_encode(p->buf, 0, MAX_MSG, &m)); \
    nbad++;                                                           \
  } while (0)
  ARM_BAD(m.q[0] = NAN);
  ARM_BAD(m.q[3] = 100.0);
  ARM_BAD(m.dq[6] = INFINITY);
  ARM_BAD(m.tau[2] = -1e9);
  ARM_BAD(m.utime = 0);
#undef ARM_BAD
  m = ok;
  const int len = nudge_arm_state_t_encode(p->buf, 0, MAX_MSG, &m);
  send(p, "ARM_STATE", len - 9);  /* cut short */
  p->buf[0] ^= 0xff;              /* wrong fingerprint */
  send(p, "ARM_STATE", len);
  memset(p->buf, 0x5a, 40);       /* too short for anything */
  send(p, "ARM_STATE", 40);
  ngarbage = 3;
  printf("inject_ARM_STATE_bad %d count\ninject_ARM_STATE_garbage %d count\n", nbad, ngarbage);
}

/* Invalid messages on every channel nudge-view reads, one broken thing each. */
static void bad_all(pub *p) {
  int n = 0;
#define BAD(T, CH, stmt)                                                 \
  do {                                                                   \
    T m;                                                                 \
    memset(&m, 0, sizeof m);                                             \
    m.utime = p->t;                                                      \
    stmt;                                                                \
    send(p, CH, T##_encode(p->buf, 0, MAX_MSG, &m));                     \
    n++;                                                                 \
  } while (0)
  BAD(nudge_mocap_t, "MOCAP", (m.obj_quat[0] = 1, m.obj_pos[0] = NAN));
  BAD(nudge_mocap_t, "MOCAP", m.obj_quat[0] = 2);
  BAD(nudge_task_t, "TASK", (m.eps = 0.01, m.time_limit = 5, m.goal_x = INFINITY));
  BAD(nudge_task_t, "TASK", (m.eps = 0, m.time_limit = 5));
  BAD(nudge_plan_t, "PLAN", (m.state_utime = p->t, m.M = 0, m.T = 0.3));
  BAD(nudge_plan_t, "PLAN", (m.state_utime = p->t, m.M = 1, m.T = 0.3, m.predicted[0] = 1e6));
  BAD(nudge_ee_cmd_t, "EE_CMD", m.mode = 9);
  BAD(nudge_ee_cmd_t, "EE_CMD", m.p[1] = NAN);
  BAD(nudge_params_t, "PARAMS", (m.theta_mean[0] = -1, m.theta_mean[3] = 1));
  BAD(nudge_arm_state_t, "ARM_STATE", m.q[2] = NAN);
  BAD(nudge_episode_t, "EPISODE", (m.reason = "", m.event = 9));
  BAD(nudge_episode_t, "EPISODE", (m.reason = "\x1b[2J", m.event = 1));
  BAD(nudge_status_t, "STATUS", (m.name = "nudge-\x1b[31mred", m.state = "running"));
  BAD(nudge_status_t, "STATUS", (m.name = "", m.state = "running"));
#undef BAD
  static const char *const chans[] = {"MOCAP", "TASK", "PLAN", "EE_CMD", "PARAMS",
                                      "STATUS", "EPISODE", "ARM_STATE"};
  for (int c = 0; c < 8; c++) {
    for (int k = 0; k < 24; k++) p->buf[k] = (unsigned char)(37 * k + 11 * c + 1);
    send(p, chans[c], 24);
    n++;
  }
  printf("inject_bad %d count\n", n);
}

/* One step's numbers: exactly n (n > 0), or at least -n (n < 0), at most 64. */
static int nums(const char *s, const char *what, int n, double *out, int *got) {
  int c = 1;
  for (const char *q = s; *q; q++) c += *q == ',';
  if (n > 0 ? c != n : (c < -n || c > 64)) {
    fprintf(stderr, PROG ": %s: '%s' needs %s%d values\n", what, s, n > 0 ? "" : "at least ",
            n > 0 ? n : -n);
    return -1;
  }
  char err[256];
  if (nd_parse_list(s, what, c, -1e9, 1e9, out, err, sizeof err)) {
    fprintf(stderr, PROG ": %s\n", err);
    return -1;
  }
  *got = c;
  return 0;
}

int main(int argc, char **argv) {
  static pub p;
  const char *url = NULL, *logpath = NULL;
  int i = 1;
  for (; i + 1 < argc && argv[i][0] == '-'; i += 2) {
    if (!strcmp(argv[i], "--lcm-url")) url = argv[i + 1];
    else if (!strcmp(argv[i], "--log")) logpath = argv[i + 1];
    else break;
  }
  if (i >= argc || argv[i][0] == '-') {
    fprintf(stderr, "usage: " PROG " [--lcm-url URL | --log FILE] STEP... (see the source)\n");
    return 2;
  }
  if (logpath ? !(p.log = lcm_eventlog_create(logpath, "w")) : !(p.lcm = lcm_create(url))) {
    fprintf(stderr, PROG ": cannot open %s\n", logpath ? logpath : "LCM");
    return 1;
  }
  p.t0 = p.t = wall_us();
  double v[64];
  int n;
  for (; i < argc; i++) {
    const char *w = argv[i], *a = i + 1 < argc ? argv[i + 1] : "";
    if (!strcmp(w, "bad-arm") || !strcmp(w, "bad")) {
      (w[3] ? bad_arm : bad_all)(&p);
      continue;
    }
    i++;
    if (!strcmp(w, "at")) {
      if (nums(a, "at", 1, v, &n)) return 2;
      p.t = p.t0 + (int64_t)llround(v[0] * 1e6);
    } else if (!strcmp(w, "mocap")) {
      if (nums(a, "mocap", 5, v, &n)) return 2;
      memcpy(p.box, v, sizeof p.box);
      mocap(&p, v[0], v[1], v[2], v[3], v[4]);
    } else if (!strcmp(w, "task")) {
      if (nums(a, "task", 4, v, &n)) return 2;
      nudge_task_t m = {p.t, ++p.task_id, v[0], v[1], v[2], v[3], 10.0, 0.0};
      send(&p, "TASK", nudge_task_t_encode(p.buf, 0, MAX_MSG, &m));
    } else if (!strcmp(w, "plan")) {
      if (nums(a, "plan", -8, v, &n) || (n - 4) % 4 || (n - 4) / 4 > 8) {
        fprintf(stderr, PROG ": plan: PX,PY,PYAW,T then 1 to 8 keypoints of 4 values\n");
        return 2;
      }
      nudge_plan_t m;
      memset(&m, 0, sizeof m);
      m.utime = m.state_utime = p.t;
      m.plan_id = ++p.plan_id;
      m.task_id = p.task_id;
      m.M = (int8_t)((n - 4) / 4);
      memcpy(m.predicted, v, 3 * sizeof(double));
      m.T = v[3];
      for (int k = 0; k < m.M; k++) memcpy(m.keypoints[k], v + 4 + 4 * k, 4 * sizeof(double));
      m.theta_version = p.version;
      send(&p, "PLAN", nudge_plan_t_encode(p.buf, 0, MAX_MSG, &m));
    } else if (!strcmp(w, "cmd")) {
      if (nums(a, "cmd", 4, v, &n)) return 2;
      cmd(&p, v[0], v[1], v[2], v[3]);
    } else if (!strcmp(w, "sweep")) {
      if (nums(a, "sweep", 5, v, &n) || !(v[4] > 0)) return 2;
      const int64_t start = p.t, steps = (int64_t)llround(v[4] * 500);
      for (int64_t k = 0; k <= steps; k++) {
        const double f = (double)k / (double)steps;
        p.t = start + k * 2000;
        const double x = v[0] + f * (v[2] - v[0]), y = v[1] + f * (v[3] - v[1]);
        cmd(&p, x, y, (v[2] - v[0]) / v[4], (v[3] - v[1]) / v[4]);
        if (k % 5 == 0) mocap(&p, p.box[0], p.box[1], p.box[2], x, y);
      }
    } else if (!strcmp(w, "params")) {
      if (nums(a, "params", 4, v, &n)) return 2;
      nudge_params_t m = {p.t, ++p.version, {v[0], v[1], v[2], v[3], 1, 0, 0},
                          {0, 0, 0, 0, 0, 0, 0}, 7, 0.0, 1};
      send(&p, "PARAMS", nudge_params_t_encode(p.buf, 0, MAX_MSG, &m));
    } else if (!strcmp(w, "status")) {
      char name[64] = "", *state = NULL;
      snprintf(name, sizeof name, "%s", a);
      if (!(state = strchr(name, ','))) return 2;
      *state++ = '\0';
      nudge_status_t m;
      memset(&m, 0, sizeof m);
      m.utime = p.t;
      m.name = name;
      m.pid = 4242;
      m.state = state;
      send(&p, "STATUS", nudge_status_t_encode(p.buf, 0, MAX_MSG, &m));
    } else if (!strcmp(w, "episode")) {
      if (nums(a, "episode", 1, v, &n)) return 2;
      char reason[] = "";
      nudge_episode_t m = {p.t, p.task_id, (int8_t)v[0], reason, 1.0, 0.001};
      send(&p, "EPISODE", nudge_episode_t_encode(p.buf, 0, MAX_MSG, &m));
    } else if (!strcmp(w, "arm")) {
      if (nums(a, "arm", 7, v, &n)) return 2;
      nudge_arm_state_t m = {p.t, ++p.seq, {0}, {0}, {0}};
      memcpy(m.q, v, sizeof m.q);
      send(&p, "ARM_STATE", nudge_arm_state_t_encode(p.buf, 0, MAX_MSG, &m));
    } else {
      fprintf(stderr, PROG ": unknown step '%s'\n", w);
      return 2;
    }
  }
  if (p.log) lcm_eventlog_destroy(p.log);
  if (p.lcm) lcm_destroy(p.lcm);
  if (p.failed) fprintf(stderr, PROG ": a message could not be %s\n", logpath ? "written" : "published");
  return p.failed;
}
