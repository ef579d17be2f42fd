/* nudge-inject: publishes malformed messages on the nudge input channels, for the process
 * tests (a test helper, not installed).
 *
 * Two kinds per channel:
 *   bad      messages that decode but must be refused by the receivers' validation
 *            (ndp_validate.h): NaN, inf, out-of-range values, each on an otherwise valid
 *            message, so that a receiver whose `rejected` counter grows by less than the
 *            number sent has let one through;
 *   garbage  messages that do not decode: random bytes, valid encodings cut short, the
 *            wrong type on the channel, and on string-carrying types string lengths that
 *            lie (negative, zero, beyond the message, no terminating NUL).
 * No message of either kind is valid, so nothing injected can move the robot.
 * A third kind, sent only when asked for (--kind workspace), is valid in every field but
 * lies outside the default workspace box: a PLAN with its keypoints at (0.8, 0), an EE_CMD
 * at (0.8, 0) and one whose future ends there. The executor and the bridge must refuse
 * these; a stack that did not
 * would move the robot toward them, which is what the test looks for.
 * A fourth, --plan-to X,Y, is valid and inside any box that holds (X, Y): PLANs that send
 * the robot there and hold, for driving an arm into a limit of its own. */
#include <lcm/lcm.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "nd_parse.h"
#include "nudge/nudge_ee_cmd_t.h"
#include "nudge/nudge_episode_t.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_params_t.h"
#include "nudge/nudge_plan_t.h"
#include "nudge/nudge_robot_state_t.h"
#include "nudge/nudge_status_t.h"
#include "nudge/nudge_task_t.h"
#include "nudge/nudge_place_t.h"

#define PROG "nudge-inject"
#define MAX_MSG 4096

/* The channels with a receiver in the process system, and STATUS (nudge-status reads it). */
enum { CH_MOCAP, CH_ROBOT_STATE, CH_EE_CMD, CH_PLAN, CH_TASK, CH_PARAMS, CH_EPISODE,
       CH_STATUS, CH_PLACE, CH_COUNT };
static const char *const ch_name[CH_COUNT] = {"MOCAP", "ROBOT_STATE", "EE_CMD", "PLAN", "TASK",
                                              "PARAMS", "EPISODE", "STATUS", "PLACE"};

/* Settings; constant once parsed. */
typedef struct {
  int on[CH_COUNT];
  int bad, garbage;    /* kinds to send */
  int workspace;       /* the valid-but-outside kind (PLAN, EE_CMD only) */
  int plan_to;         /* valid PLANs to `to` (PLAN only) */
  double to[2];
  int place_at;        /* one valid PLACE at `at` (PLACE only): the object bumped there */
  double at[3];
  uint64_t place_id;   /* with place_at: this id, a re-sent PLACE; 0: a new one */
  int repeat;
  double gap_s;        /* pause after each message */
  uint64_t seed;
  const char *url;
} inj_opts;

/* What one run sends: the bus, counters per channel, a scratch buffer. */
typedef struct {
  lcm_t *lcm;
  const inj_opts *o;
  int ch;
  int64_t n_bad[CH_COUNT], n_garbage[CH_COUNT], n_ws[CH_COUNT];
  int failed;
  uint64_t rng;
  unsigned char buf[MAX_MSG];
} inj;

static int64_t wall_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

static uint64_t next_rand(uint64_t *s) {
  /* xorshift64*: reproducible garbage for a seed. */
  *s ^= *s >> 12;
  *s ^= *s << 25;
  *s ^= *s >> 27;
  return *s * 2685821657736338717ULL;
}

static void pause_gap(const inj *j) {
  if (j->o->gap_s <= 0.0) return;
  struct timespec ts = {(time_t)j->o->gap_s, (long)(fmod(j->o->gap_s, 1.0) * 1e9)};
  while (nanosleep(&ts, &ts) != 0) {
  }
}

enum { K_GARBAGE, K_BAD, K_WS };

static void send_raw(inj *j, const void *data, int len, int kind) {
  if (lcm_publish(j->lcm, ch_name[j->ch], data, (unsigned)len) != 0) j->failed = 1;
  if (kind == K_BAD) j->n_bad[j->ch]++;
  else if (kind == K_WS) j->n_ws[j->ch]++;
  else j->n_garbage[j->ch]++;
  pause_gap(j);
}

/* Publish the len bytes in j->buf as a message of the workspace kind. */
static void send_ws(inj *j, int len) {
  if (len <= 0) {
    j->failed = 1;
    return;
  }
  send_raw(j, j->buf, len, K_WS);
}

/* Publish the len bytes encoded in j->buf as a bad message (if that kind is on). */
static void send_enc(inj *j, int len) {
  if (len <= 0) {
    j->failed = 1;
    return;
  }
  if (j->o->bad) send_raw(j, j->buf, len, K_BAD);
}

/* Garbage common to every channel: random bytes of several lengths (wrong fingerprint
 * with overwhelming probability), the channel's valid template cut short (right
 * fingerprint, too few bytes), and another type's encoding. tmpl/tlen: a valid encoding
 * of the channel's type. */
static void send_garbage(inj *j, const unsigned char *tmpl, int tlen) {
  static const int lens[] = {0, 1, 7, 8, 9, 16, 33, 100, 333, 1400};
  unsigned char g[1400];
  for (size_t k = 0; k < sizeof lens / sizeof lens[0]; k++) {
    for (int i = 0; i < lens[k]; i++) g[i] = (unsigned char)next_rand(&j->rng);
    send_raw(j, g, lens[k], 0);
  }
  const int cuts[] = {8, 9, 16, tlen / 2, tlen - 1};
  for (size_t k = 0; k < sizeof cuts / sizeof cuts[0]; k++)
    if (cuts[k] > 0 && cuts[k] < tlen) send_raw(j, tmpl, cuts[k], 0);
  /* The wrong type: a task on this channel (a mocap frame on TASK). */
  unsigned char w[512];
  int wl;
  if (j->ch != CH_TASK) {
    nudge_task_t t = {wall_us(), 1, 0.1, 0.0, 0.0, 1e-2, 5.0, 0.0};
    wl = nudge_task_t_encode(w, 0, sizeof w, &t);
  } else {
    nudge_mocap_t m = {wall_us(), 1, {0, 0, 0.05}, {1, 0, 0, 0}, {-0.1, 0, 0.05}};
    wl = nudge_mocap_t_encode(w, 0, sizeof w, &m);
  }
  if (wl > 0) send_raw(j, w, wl, 0);
}

/* A string field whose length word lies: at byte off of an encoding of len bytes (in
 * j->buf) sits the int32 length of a string of slen bytes (NUL included). */
static void send_bad_strings(inj *j, int len, int off, int slen) {
  unsigned char save[4];
  memcpy(save, j->buf + off, 4);
  const int32_t lies[] = {-1, INT32_MIN, 0, 0x7fffffff, len};
  for (size_t k = 0; k < sizeof lies / sizeof lies[0]; k++) {
    const uint32_t v = (uint32_t)lies[k];
    j->buf[off] = (unsigned char)(v >> 24);
    j->buf[off + 1] = (unsigned char)(v >> 16);
    j->buf[off + 2] = (unsigned char)(v >> 8);
    j->buf[off + 3] = (unsigned char)v;
    send_raw(j, j->buf, len, 0);
  }
  memcpy(j->buf + off, save, 4);
  /* The right length, but no terminating NUL: a reader's strlen would run off the end. */
  const unsigned char nul = j->buf[off + 4 + slen - 1];
  j->buf[off + 4 + slen - 1] = 'x';
  send_raw(j, j->buf, len, 0);
  j->buf[off + 4 + slen - 1] = nul;
}

/* ---- one function per channel: a valid template, then one broken field at a time ---- */

static void inject_mocap(inj *j) {
  const nudge_mocap_t ok = {wall_us(), 1, {0, 0, 0.05}, {1, 0, 0, 0}, {-0.1, 0, 0.05}};
  nudge_mocap_t m;
#define MOCAP_BAD(stmt)                                                 \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_mocap_t_encode(j->buf, 0, MAX_MSG, &m));          \
  } while (0)
  MOCAP_BAD(m.utime = 0);
  MOCAP_BAD(m.obj_pos[0] = NAN);
  MOCAP_BAD(m.obj_pos[1] = INFINITY);
  MOCAP_BAD(m.obj_pos[2] = -1e9);
  MOCAP_BAD(m.ee_pos[0] = -INFINITY);
  MOCAP_BAD(m.ee_pos[1] = 1e6);
  MOCAP_BAD(m.obj_quat[0] = 2.0);
  MOCAP_BAD(m.obj_quat[0] = 0.0);
  MOCAP_BAD(m.obj_quat[3] = NAN);
  MOCAP_BAD((m.obj_quat[0] = 0.5, m.obj_quat[1] = 0.5));
#undef MOCAP_BAD
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_mocap_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_robot_state(inj *j) {
  const nudge_robot_state_t ok = {.utime = wall_us(), .seq = 1, .ee_pos = {-0.1, 0, 0.05}};
  nudge_robot_state_t m;
#define RS_BAD(stmt)                                                    \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_robot_state_t_encode(j->buf, 0, MAX_MSG, &m));    \
  } while (0)
  RS_BAD(m.utime = -5);
  RS_BAD(m.ee_pos[0] = NAN);
  RS_BAD(m.ee_pos[1] = 1e9);
  RS_BAD(m.ee_pos[2] = -INFINITY);
  RS_BAD(m.ee_vel[0] = INFINITY);
  RS_BAD(m.ee_vel[1] = 1e5);
  RS_BAD(m.ee_force[2] = NAN);
  RS_BAD(m.ee_force[0] = 1e12);
#undef RS_BAD
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_robot_state_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_ee_cmd(inj *j) {
  const int64_t now = wall_us();
  const nudge_ee_cmd_t ok = {.utime = now, .seq = 1, .plan_id = 1, .plan_utime = now - 1000,
                             .mode = 0, .p = {-0.1, 0, 0.05}, .seg_end_utime = now,
                             .seg_key = {-0.1, 0, 0, 0}, .brake_utime = now,
                             .rest_utime = now, .hold = {-0.1, 0}};
  nudge_ee_cmd_t m;
#define CMD_BAD(stmt)                                                   \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_ee_cmd_t_encode(j->buf, 0, MAX_MSG, &m));         \
  } while (0)
  CMD_BAD(m.utime = 0);
  CMD_BAD(m.p[0] = NAN);
  CMD_BAD(m.p[1] = 1e6);
  CMD_BAD(m.p[2] = -INFINITY);
  CMD_BAD(m.v[0] = INFINITY);
  CMD_BAD(m.v[1] = -1e4);
  CMD_BAD(m.a[0] = NAN);
  CMD_BAD(m.a[1] = 1e9);
  CMD_BAD(m.j[0] = NAN);
  CMD_BAD(m.j[1] = -1e7);
  CMD_BAD(m.mode = 7);
  CMD_BAD(m.mode = -1);
  CMD_BAD(m.plan_utime = -1);
  CMD_BAD(m.seg_key[0] = NAN);
  CMD_BAD(m.seg_key[3] = 1e4);
  CMD_BAD(m.hold[1] = INFINITY);
  CMD_BAD(m.seg_end_utime = 0);
  CMD_BAD(m.rest_utime = now + 3600000000LL);
  CMD_BAD(m.brake_utime = now + 1000);
#undef CMD_BAD
  if (j->o->workspace) {
    m = ok;
    m.p[0] = 0.8;
    send_ws(j, nudge_ee_cmd_t_encode(j->buf, 0, MAX_MSG, &m));
    /* A future ending there: a robot follows it while the commander is silent. */
    m = ok;
    m.seg_key[0] = m.hold[0] = 0.8;
    m.seg_end_utime = m.brake_utime = now + 100000;
    m.rest_utime = now + 200000;
    send_ws(j, nudge_ee_cmd_t_encode(j->buf, 0, MAX_MSG, &m));
  }
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_ee_cmd_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_plan(inj *j) {
  nudge_plan_t ok;
  memset(&ok, 0, sizeof ok);
  ok.utime = ok.state_utime = wall_us();
  ok.plan_id = 1000000;
  ok.task_id = 1;
  ok.M = 2;
  ok.keypoints[0][0] = -0.1;
  ok.keypoints[1][0] = -0.05;
  ok.T = 0.3;
  nudge_plan_t m;
#define PLAN_BAD(stmt)                                                  \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_plan_t_encode(j->buf, 0, MAX_MSG, &m));           \
  } while (0)
  PLAN_BAD(m.M = 0);
  PLAN_BAD(m.M = 99);
  PLAN_BAD(m.M = -1);
  PLAN_BAD(m.T = 0.0);
  PLAN_BAD(m.T = -0.3);
  PLAN_BAD(m.T = NAN);
  PLAN_BAD(m.T = INFINITY);
  PLAN_BAD(m.T = 1e6);
  PLAN_BAD(m.keypoints[0][0] = NAN);
  PLAN_BAD(m.keypoints[0][1] = 1e6);
  PLAN_BAD(m.keypoints[1][2] = INFINITY);
  PLAN_BAD(m.keypoints[0][3] = -1e3);
  PLAN_BAD(m.utime = 0);
  PLAN_BAD(m.state_utime = -1);
  PLAN_BAD(m.start_utime = -5);
#undef PLAN_BAD
  if (j->o->plan_to) {
    m = ok;
    m.plan_id = 3000000 + j->n_ws[CH_PLAN];
    m.utime = m.state_utime = wall_us();
    m.T = 0.5;
    for (int k = 0; k < 2; k++) m.keypoints[0][k] = m.keypoints[1][k] = j->o->to[k];
    send_ws(j, nudge_plan_t_encode(j->buf, 0, MAX_MSG, &m));
  }
  if (j->o->workspace) {
    m = ok;
    m.plan_id = 2000000 + j->n_ws[CH_PLAN];
    m.utime = m.state_utime = wall_us();
    m.keypoints[0][0] = m.keypoints[1][0] = 0.8;
    send_ws(j, nudge_plan_t_encode(j->buf, 0, MAX_MSG, &m));
  }
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_plan_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_task(inj *j) {
  /* Template: a reachable goal; only ever sent with one field broken. */
  const nudge_task_t ok = {wall_us(), 1000000, 0.1, 0.0, 0.0, 1e-2, 5.0, 0.0};
  nudge_task_t m;
#define TASK_BAD(stmt)                                                  \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_task_t_encode(j->buf, 0, MAX_MSG, &m));           \
  } while (0)
  TASK_BAD(m.eps = 0.0);
  TASK_BAD(m.eps = -1.0);
  TASK_BAD(m.eps = NAN);
  TASK_BAD(m.time_limit = 0.0);
  TASK_BAD(m.time_limit = -5.0);
  TASK_BAD(m.time_limit = INFINITY);
  TASK_BAD(m.goal_x = NAN);
  TASK_BAD(m.goal_y = 1e6);
  TASK_BAD(m.goal_yaw = INFINITY);
  TASK_BAD(m.v_max = -0.1);
  TASK_BAD(m.v_max = NAN);
  TASK_BAD(m.v_max = 1e3);
  TASK_BAD(m.task_id = -3);
  TASK_BAD(m.utime = 0);
#undef TASK_BAD
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_task_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_place(inj *j) {
  /* Template: the start pose; only ever sent with one field broken. */
  const nudge_place_t ok = {wall_us(), 1000000, 0.0, 0.0, 0.0, 0.01, 0, 0.0, 0.0};
  nudge_place_t m;
#define PLACE_BAD(stmt)                                                 \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_place_t_encode(j->buf, 0, MAX_MSG, &m));          \
  } while (0)
  PLACE_BAD(m.x = NAN);
  PLACE_BAD(m.y = 1e6);
  PLACE_BAD(m.yaw = INFINITY);
  PLACE_BAD(m.clear = -0.01);
  PLACE_BAD(m.clear = NAN);
  PLACE_BAD(m.clear = 5.0);
  PLACE_BAD(m.place_id = -2);
  PLACE_BAD(m.utime = 0);
  PLACE_BAD(m.park = 2);
  PLACE_BAD((m.park = 1, m.park_x = NAN));
  PLACE_BAD((m.park = 1, m.park_y = 1e6));
#undef PLACE_BAD
  if (j->o->place_at) {
    m = ok;
    m.utime = m.place_id = wall_us();  /* a new placement: ids only increase */
    if (j->o->place_id) m.place_id = (int64_t)j->o->place_id;
    m.x = j->o->at[0], m.y = j->o->at[1], m.yaw = j->o->at[2];
    send_ws(j, nudge_place_t_encode(j->buf, 0, MAX_MSG, &m));
  }
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_place_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_params(inj *j) {
  const nudge_params_t ok = {wall_us(), 1000000, {1, 0.005, 1e-4, 1, 1, 0, 0},
                             {0, 0, 0, 0, 0, 0, 0}, 15, 0.0, 1};
  nudge_params_t m;
#define PAR_BAD(stmt)                                                   \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_params_t_encode(j->buf, 0, MAX_MSG, &m));         \
  } while (0)
  PAR_BAD(m.theta_mean[3] = -1.0);
  PAR_BAD(m.theta_mean[3] = 0.0);
  PAR_BAD(m.theta_mean[0] = -0.5);
  PAR_BAD(m.theta_mean[1] = NAN);
  PAR_BAD(m.theta_mean[2] = INFINITY);
  PAR_BAD(m.theta_mean[0] = 1e9);
  PAR_BAD(m.theta_std[0] = INFINITY);
  PAR_BAD(m.theta_std[3] = -1.0);
  PAR_BAD(m.theta_mean[4] = 0.0);  /* box_scale */
  PAR_BAD(m.theta_mean[5] = 0.2);  /* com_x */
  PAR_BAD(m.version = -1);
  PAR_BAD(m.buffer_size = -1);
  PAR_BAD(m.utime = 0);
#undef PAR_BAD
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_params_t_encode(j->buf, 0, MAX_MSG, &m));
  }
}

static void inject_episode(inj *j) {
  char reason[] = "injected";
  const nudge_episode_t ok = {wall_us(), 1000000, NUDGE_EPISODE_T_EVENT_TIMEOUT, reason, 1.0,
                              0.5};
  nudge_episode_t m;
#define EPI_BAD(stmt)                                                   \
  do {                                                                  \
    m = ok;                                                             \
    stmt;                                                               \
    send_enc(j, nudge_episode_t_encode(j->buf, 0, MAX_MSG, &m));        \
  } while (0)
  EPI_BAD(m.event = 9);
  EPI_BAD(m.event = -1);
  EPI_BAD(m.task_id = -1);
  EPI_BAD(m.utime = 0);
#undef EPI_BAD
  if (j->o->garbage) {
    m = ok;
    send_garbage(j, j->buf, nudge_episode_t_encode(j->buf, 0, MAX_MSG, &m));
    /* fingerprint, utime, task_id, event: the reason's length word at byte 25. */
    const int len = nudge_episode_t_encode(j->buf, 0, MAX_MSG, &m);
    send_bad_strings(j, len, 8 + 8 + 8 + 1, (int)sizeof reason);
  }
}

static void inject_status(inj *j) {
  char name[] = "nudge-injected", state[] = "injected";
  nudge_status_t m;
  memset(&m, 0, sizeof m);
  m.utime = wall_us();
  m.name = name;
  m.pid = 1;
  m.state = state;
  /* No receiver validates heartbeats: only garbage here. */
  if (j->o->garbage) {
    send_garbage(j, j->buf, nudge_status_t_encode(j->buf, 0, MAX_MSG, &m));
    /* fingerprint, utime: the name's length word at byte 16; the state's after the name
     * and the pid. */
    const int len = nudge_status_t_encode(j->buf, 0, MAX_MSG, &m);
    send_bad_strings(j, len, 16, (int)sizeof name);
    send_bad_strings(j, len, 16 + 4 + (int)sizeof name + 4, (int)sizeof state);
    /* Well-formed, but a name that would drive a terminal (clear screen, red), and one
     * longer than any process name: a viewer must print neither. */
    char esc[] = "nudge-\x1b[2J\x1b[31mhijacked", longname[200];
    memset(longname, 'n', sizeof longname - 1);
    longname[sizeof longname - 1] = 0;
    char *names[2] = {esc, longname};
    for (int k = 0; k < 2; k++) {
      m.name = names[k];
      const int l = nudge_status_t_encode(j->buf, 0, MAX_MSG, &m);
      if (l > 0) send_raw(j, j->buf, l, 0);
      else j->failed = 1;
    }
    m.name = name;
  }
}

/* ---- command line ------------------------------------------------------------------- */

static void usage(FILE *f) {
  fprintf(f,
          "usage: " PROG " [options]\n"
          "Publish malformed messages on the nudge input channels: 'bad' ones decode but\n"
          "carry NaN, inf or out-of-range values (receivers must refuse and count each);\n"
          "'garbage' does not decode (random bytes, truncated encodings, the wrong type,\n"
          "lying string lengths). Nothing sent is valid.\n\n"
          "  --channel CH    one of MOCAP ROBOT_STATE EE_CMD PLAN TASK PARAMS EPISODE STATUS\n"
          "                  PLACE;\n"
          "                  repeat for more (default: all but STATUS)\n"
          "  --kind K        bad, garbage or all (default all); or workspace: valid PLAN\n"
          "                  and EE_CMD outside the default workspace (at (0.8, 0))\n"
          "  --plan-to X,Y   instead: valid PLANs to (X, Y), on PLAN only (with --repeat\n"
          "                  and --gap-ms: a stream the executor follows)\n"
          "  --place-at X,Y,YAW  instead: one valid PLACE there, on PLACE only (an emulating\n"
          "                  bridge puts the object there: a bump between tasks)\n"
          "  --place-id ID   with --place-at: that place_id, as a sender re-sending an\n"
          "                  older PLACE does (default: a new one)\n"
          "  --repeat N      send everything N times, 1..10000 (default 1)\n"
          "  --gap-ms MS     pause after each message, 0..1000 ms (default 1)\n"
          "  --seed N        seed of the random garbage (default 1)\n"
          "  --lcm-url URL   default $LCM_DEFAULT_URL, else LCM's default\n"
          "  -h, --help      this text\n\n"
          "Prints per channel 'inject_<CH>_bad N count' and 'inject_<CH>_garbage N count'\n"
          "(and 'inject_<CH>_workspace N count').\n"
          "Exit status 0, 1 if LCM failed, 2 on bad arguments.\n");
}

static int bad_arg(const char *msg) {
  fprintf(stderr, PROG ": %s\n", msg);
  usage(stderr);
  return 2;
}

static int parse_args(int argc, char **argv, inj_opts *o) {
  char err[256];
  int any = 0;
  memset(o, 0, sizeof *o);
  o->bad = o->garbage = 1;
  o->repeat = 1;
  o->gap_s = 1e-3;
  o->seed = 1;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
      usage(stdout);
      return 0;
    }
    if (strcmp(a, "--channel") && strcmp(a, "--kind") && strcmp(a, "--repeat") &&
        strcmp(a, "--gap-ms") && strcmp(a, "--seed") && strcmp(a, "--lcm-url") &&
        strcmp(a, "--plan-to") && strcmp(a, "--place-at") && strcmp(a, "--place-id")) {
      snprintf(err, sizeof err, "unknown argument '%s'", a);
      return bad_arg(err);
    }
    if (i + 1 >= argc) {
      snprintf(err, sizeof err, "%s needs a value", a);
      return bad_arg(err);
    }
    const char *v = argv[++i];
    if (!strcmp(a, "--channel")) {
      int c = 0;
      while (c < CH_COUNT && strcmp(v, ch_name[c])) c++;
      if (c == CH_COUNT) {
        snprintf(err, sizeof err, "--channel: unknown channel '%s'", v);
        return bad_arg(err);
      }
      o->on[c] = 1;
      any = 1;
    } else if (!strcmp(a, "--kind")) {
      if (!strcmp(v, "bad")) o->garbage = 0;
      else if (!strcmp(v, "garbage")) o->bad = 0;
      else if (!strcmp(v, "workspace")) o->bad = o->garbage = 0, o->workspace = 1;
      else if (strcmp(v, "all")) return bad_arg("--kind: expected bad, garbage, all or workspace");
    } else if (!strcmp(a, "--plan-to")) {
      if (nd_parse_list(v, a, 2, -1.0, 1.0, o->to, err, sizeof err)) return bad_arg(err);
      o->bad = o->garbage = 0, o->plan_to = 1;
      o->on[CH_PLAN] = 1, any = 1;
    } else if (!strcmp(a, "--place-at")) {
      if (nd_parse_list(v, a, 3, -3.2, 3.2, o->at, err, sizeof err)) return bad_arg(err);
      o->bad = o->garbage = 0, o->place_at = 1;
      o->on[CH_PLACE] = 1, any = 1;
    } else if (!strcmp(a, "--place-id")) {
      if (nd_parse_u64(v, a, &o->place_id, err, sizeof err)) return bad_arg(err);
      if (o->place_id < 1 || o->place_id > INT64_MAX)
        return bad_arg("--place-id: expected 1..2^63-1");
    } else if (!strcmp(a, "--repeat")) {
      if (nd_parse_int(v, a, 1, 10000, &o->repeat, err, sizeof err)) return bad_arg(err);
    } else if (!strcmp(a, "--gap-ms")) {
      if (nd_parse_double(v, a, 0.0, 1000.0, &o->gap_s, err, sizeof err)) return bad_arg(err);
      o->gap_s *= 1e-3;
    } else if (!strcmp(a, "--seed")) {
      if (nd_parse_u64(v, a, &o->seed, err, sizeof err)) return bad_arg(err);
      if (o->seed == 0) o->seed = 1;   /* xorshift's one fixed point */
    } else {
      o->url = v;
    }
  }
  if (o->place_id && !o->place_at) return bad_arg("--place-id needs --place-at");
  if (!any)
    for (int c = 0; c < CH_COUNT; c++) o->on[c] = c != CH_STATUS;
  return -1;
}

int main(int argc, char **argv) {
  static inj_opts o;
  static inj j;
  const int rc = parse_args(argc, argv, &o);
  if (rc >= 0) return rc;

  j.o = &o;
  j.rng = o.seed;
  j.lcm = lcm_create(o.url);
  if (!j.lcm) {
    fprintf(stderr, PROG ": cannot create LCM on %s (no multicast route?)\n",
            o.url ? o.url : "the default URL");
    return 1;
  }
  static void (*const fn[CH_COUNT])(inj *) = {inject_mocap, inject_robot_state, inject_ee_cmd,
                                              inject_plan,  inject_task,        inject_params,
                                              inject_episode, inject_status, inject_place};
  for (int r = 0; r < o.repeat; r++)
    for (int c = 0; c < CH_COUNT; c++)
      if (o.on[c]) {
        j.ch = c;
        fn[c](&j);
      }
  int64_t tb = 0, tg = 0;
  for (int c = 0; c < CH_COUNT; c++) {
    if (!o.on[c]) continue;
    printf("inject_%s_bad %lld count\n", ch_name[c], (long long)j.n_bad[c]);
    printf("inject_%s_garbage %lld count\n", ch_name[c], (long long)j.n_garbage[c]);
    if (o.workspace)
      printf("inject_%s_workspace %lld count\n", ch_name[c], (long long)j.n_ws[c]);
    tb += j.n_bad[c];
    tg += j.n_garbage[c];
  }
  printf("inject_bad %lld count\ninject_garbage %lld count\n", (long long)tb, (long long)tg);
  lcm_destroy(j.lcm);
  if (j.failed) {
    fprintf(stderr, PROG ": some messages could not be encoded or published\n");
    return 1;
  }
  return 0;
}
