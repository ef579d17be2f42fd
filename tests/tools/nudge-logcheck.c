/* nudge-logcheck: figures and checks from an lcm-logger log of a nudge run, and from its
 * replay buffer and parameter history files, for the process tests (a test helper, not
 * installed).
 *
 * Reads the log with LCM's eventlog API, decodes the nudge channels with the generated
 * decoders (strings through ndp's safe decoders: a log of a bad-input test holds lying
 * string lengths), prints 'name value unit' lines and exits 1 when a check asked for on
 * the command line fails, naming it on stderr. Message times are the utime fields
 * (publication wall clock, us), not the logger's receive stamps. A log still being
 * written is fine: a half-written last event ends the reading. */
#include <lcm/eventlog.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_exec.h"
#include "nd_parse.h"
#include "nd_rbuf.h"
#include "nd_stats.h"
#include "ndp.h"
#include "nd_history.h"
#include "nd_math.h"
#include "nd_release.h"
#include "nds_model.h"
#include "ndp_validate.h"

#define PROG "nudge-logcheck"

/* Everything the subcommands take; one struct, filled by the parser. */
typedef struct {
  const char *cmd, *log;
  const char *arg;         /* status: process name; last: channel */
  const char *state;       /* status: only heartbeats whose state starts with this */
  const char *committed;   /* buffer: file of committed task ids */
  const char *buffer;      /* history: the replay buffer it was fitted on */
  int allow_torn;          /* buffer, history: a torn tail is no failure */
  double timeout;          /* stale-cmds: the executor's plan timeout, s */
  double slack_ms;         /* stale-cmds: allowance on it */
  /* checks, negative = not asked for */
  int min_start, min_success, min_end;
  int first_success;
  double max_gap_ms;
  double max_ms;           /* stop-after */
  int or_replanned;        /* stop-after: a brake a new plan took over passes too */
  double min_speed;        /* live */
  double max_travel;       /* ee-pos */
  int min_plans;           /* live */
  /* windows and references, 0 = unset */
  int64_t t0, before, after, from, to;
  int64_t pid;
  double slack_us;         /* ee-cmd: allowance on each dt for clock-read jitter */
  nd_exec_cfg lim;
} lc_opts;

static int failures;

/* Name a failed check on stderr and remember it for the exit status. */
static void fail(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static void fail(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, PROG ": CHECK FAILED: ");
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
  failures++;
}

/* ---- reading ------------------------------------------------------------------------ */

typedef void (*visit_fn)(const lcm_eventlog_event_t *ev, void *user);

/* Call fn on every event of the log (channel NULL) or of one channel. -1 if the log
 * cannot be opened. */
static int for_each(const char *path, const char *channel, visit_fn fn, void *user) {
  lcm_eventlog_t *log = lcm_eventlog_create(path, "r");
  if (!log) {
    fprintf(stderr, PROG ": cannot open the log %s\n", path);
    return -1;
  }
  lcm_eventlog_event_t *ev;
  while ((ev = lcm_eventlog_read_next_event(log)) != NULL) {
    if (!channel || !strcmp(ev->channel, channel)) fn(ev, user);
    lcm_eventlog_free_event(ev);
  }
  lcm_eventlog_destroy(log);
  return 0;
}

static double norm3(const double v[3]) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

static double dist3(const double a[3], const double b[3]) {
  const double d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
  return norm3(d);
}

/* ---- episodes ----------------------------------------------------------------------- */

#define MAX_TASKS 64

typedef struct {
  int64_t n[5];                 /* per event kind */
  int64_t id[MAX_TASKS];        /* task ids in start order */
  int end_event[MAX_TASKS];     /* -1 while not ended */
  double end_time[MAX_TASKS];
  int64_t end_utime[MAX_TASKS];
  int ntask;
  int64_t undecodable;
} ep_acc;

static void ep_visit(const lcm_eventlog_event_t *ev, void *user) {
  ep_acc *a = user;
  nudge_episode_t m;
  char why[160];
  if (ndp_decode_episode(ev->data, ev->datalen, &m, why, sizeof why)) {
    a->undecodable++;
    return;
  }
  /* A bad-input test's log holds refused events too: count only what a receiver takes. */
  if (m.utime > 0 && m.event >= 0 && m.event <= NUDGE_EPISODE_T_EVENT_STOPPED &&
      m.task_id >= 0) {
    a->n[m.event]++;
    if (m.event == NUDGE_EPISODE_T_EVENT_START) {
      if (a->ntask < MAX_TASKS) {
        a->id[a->ntask] = m.task_id;
        a->end_event[a->ntask] = -1;
        a->ntask++;
      }
    } else {
      for (int i = 0; i < a->ntask; i++)
        if (a->id[i] == m.task_id && a->end_event[i] < 0) {
          a->end_event[i] = m.event;
          a->end_time[i] = m.time;
          a->end_utime[i] = m.utime;
        }
    }
  }
  nudge_episode_t_decode_cleanup(&m);
}

static int cmd_episodes(const lc_opts *o) {
  static const char *word[5] = {"start", "success", "timeout", "rejected", "stopped"};
  ep_acc a;
  memset(&a, 0, sizeof a);
  if (for_each(o->log, NDP_CH_EPISODE, ep_visit, &a)) return 1;
  for (int k = 0; k < 5; k++) printf("episodes_%s %lld count\n", word[k], (long long)a.n[k]);
  int ended = 0;
  for (int i = 0; i < a.ntask; i++) {
    if (a.end_event[i] < 0) {
      printf("episode_%d_unfinished 0 s\n", i + 1);
      continue;
    }
    ended++;
    printf("episode_%d_%s %.3f s\n", i + 1, word[a.end_event[i]], a.end_time[i]);
    printf("episode_%d_end_utime %lld us\n", i + 1, (long long)a.end_utime[i]);
  }
  printf("episodes_ended %d count\n", ended);
  if (a.undecodable) printf("episodes_undecodable %lld count\n", (long long)a.undecodable);
  if (o->min_start >= 0 && a.n[0] < o->min_start)
    fail("%lld tasks started, expected at least %d", (long long)a.n[0], o->min_start);
  if (o->min_success >= 0 && a.n[1] < o->min_success)
    fail("%lld tasks reached their goal, expected at least %d", (long long)a.n[1], o->min_success);
  if (o->min_end >= 0 && ended < o->min_end)
    fail("%d tasks ended, expected at least %d", ended, o->min_end);
  if (o->first_success && (a.ntask == 0 || a.end_event[0] != NUDGE_EPISODE_T_EVENT_SUCCESS))
    fail("the first task did not reach its goal (%d tasks started)", a.ntask);
  return 0;
}

/* ---- ee-cmd: setpoint stream continuity --------------------------------------------- */

typedef struct {
  const lc_opts *o;
  int have;
  nudge_ee_cmd_t prev;
  int64_t count, lost, backwards, switches, undecodable;
  /* Gaps between setpoints the executor sent one after the other (seq + 1): its own
   * stalls. Across setpoints missing from the log (the logger starved, not the robot's
   * problem) only the log's gap is reported. */
  double gap_max_ms, gap_sum_ms, log_gap_max_ms;
  int64_t gaps, gap_over;       /* gaps beyond --max-gap-ms */
  double r_max[3];              /* |dp|/(v_max dt'), |dv|/(a_max dt'), |da|/(j_max dt') */
  double r_sw[3];               /* the same at plan switches */
  double d_sw[3];               /* largest |dp|, |dv|, |da| at a plan switch */
  double v_max_seen, a_max_seen;
  int64_t t_first, t_last;
} cmd_acc;

static void cmd_visit(const lcm_eventlog_event_t *ev, void *user) {
  cmd_acc *c = user;
  nudge_ee_cmd_t m;
  if (nudge_ee_cmd_t_decode(ev->data, 0, ev->datalen, &m) < 0) {
    c->undecodable++;
    return;
  }
  char why[160];
  /* Injected bad setpoints are in a bad-input test's log too: they are not the executor's. */
  if (ndp_check_ee_cmd(&m, why, sizeof why)) return;
  if ((c->o->from && m.utime < c->o->from) || (c->o->to && m.utime > c->o->to)) return;
  c->count++;
  const double v = norm3(m.v), a = norm3(m.a);
  if (v > c->v_max_seen) c->v_max_seen = v;
  if (a > c->a_max_seen) c->a_max_seen = a;
  if (!c->have) {
    c->have = 1;
    c->t_first = m.utime;
  } else {
    const nudge_ee_cmd_t *p = &c->prev;
    if (m.seq > p->seq + 1) c->lost += m.seq - p->seq - 1;
    const double dt_us = (double)(m.utime - p->utime);
    if (dt_us <= 0.0) {
      c->backwards++;
    } else {
      const double gap_ms = 1e-3 * dt_us;
      if (gap_ms > c->log_gap_max_ms) c->log_gap_max_ms = gap_ms;
      if (m.seq == p->seq + 1) {
        c->gaps++;
        c->gap_sum_ms += gap_ms;
        if (gap_ms > c->gap_max_ms) c->gap_max_ms = gap_ms;
        if (c->o->max_gap_ms >= 0 && gap_ms > c->o->max_gap_ms) c->gap_over++;
      }
      /* Between two setpoints dt apart, a trajectory within the limits moves at most
       * v_max dt, changes velocity by at most a_max dt and acceleration by j_max dt. */
      const double dt = 1e-6 * (dt_us + c->o->slack_us);
      const double d[3] = {dist3(m.p, p->p), dist3(m.v, p->v), dist3(m.a, p->a)};
      const double lim[3] = {c->o->lim.v_max, c->o->lim.a_max, c->o->lim.j_max};
      const int sw = m.plan_id != p->plan_id;
      if (sw) c->switches++;
      for (int k = 0; k < 3; k++) {
        const double r = d[k] / (lim[k] * dt);
        if (r > c->r_max[k]) c->r_max[k] = r;
        if (sw && r > c->r_sw[k]) c->r_sw[k] = r;
        if (sw && d[k] > c->d_sw[k]) c->d_sw[k] = d[k];
      }
    }
  }
  c->prev = m;
  c->t_last = m.utime;
}

static int cmd_ee_cmd(const lc_opts *o) {
  cmd_acc c;
  memset(&c, 0, sizeof c);
  c.o = o;
  if (for_each(o->log, NDP_CH_EE_CMD, cmd_visit, &c)) return 1;
  const double span = 1e-6 * (double)(c.t_last - c.t_first);
  printf("ee_cmd_count %lld count\n", (long long)c.count);
  printf("ee_cmd_span %.3f s\n", span);
  printf("ee_cmd_rate %.1f Hz\n", span > 0 ? (double)(c.count - 1) / span : 0.0);
  printf("ee_cmd_seq_lost %lld count\n", (long long)c.lost);
  printf("ee_cmd_gap_mean %.3f ms\n", c.gaps ? c.gap_sum_ms / (double)c.gaps : 0.0);
  printf("ee_cmd_gap_max %.3f ms\n", c.gap_max_ms);
  printf("ee_cmd_log_gap_max %.3f ms\n", c.log_gap_max_ms);
  printf("ee_cmd_speed_max %.4f m/s\n", c.v_max_seen);
  printf("ee_cmd_acc_max %.4f m/s^2\n", c.a_max_seen);
  printf("ee_cmd_dp_ratio_max %.4f of_v_max_dt\n", c.r_max[0]);
  printf("ee_cmd_dv_ratio_max %.4f of_a_max_dt\n", c.r_max[1]);
  printf("ee_cmd_da_ratio_max %.4f of_j_max_dt\n", c.r_max[2]);
  printf("plan_switches %lld count\n", (long long)c.switches);
  printf("switch_dp_ratio_max %.4f of_v_max_dt\n", c.r_sw[0]);
  printf("switch_dv_ratio_max %.4f of_a_max_dt\n", c.r_sw[1]);
  printf("switch_da_ratio_max %.4f of_j_max_dt\n", c.r_sw[2]);
  printf("switch_dp_max %.6f m\n", c.d_sw[0]);
  printf("switch_dv_max %.6f m/s\n", c.d_sw[1]);
  printf("switch_da_max %.6f m/s^2\n", c.d_sw[2]);
  if (c.undecodable) printf("ee_cmd_undecodable %lld count\n", (long long)c.undecodable);
  if (c.count < 2) fail("%lld EE_CMD setpoints in the log, need at least 2", (long long)c.count);
  if (c.backwards) fail("%lld setpoints not later than the one before", (long long)c.backwards);
  if (o->max_gap_ms >= 0 && c.gap_over)
    fail("%lld gaps between setpoints beyond %g ms (largest %.1f ms)", (long long)c.gap_over,
         o->max_gap_ms, c.gap_max_ms);
  if (c.v_max_seen > o->lim.v_max) fail("setpoint speed %g m/s beyond v_max %g", c.v_max_seen, o->lim.v_max);
  if (c.a_max_seen > o->lim.a_max)
    fail("setpoint acceleration %g m/s^2 beyond a_max %g", c.a_max_seen, o->lim.a_max);
  static const char *what[3] = {"position", "velocity", "acceleration"};
  for (int k = 0; k < 3; k++) {
    if (c.r_max[k] > 1.0) {
      fail("%s jumps: a step is %g times what the limits allow (at plan switches: %g)",
           what[k], c.r_max[k], c.r_sw[k]);
    }
  }
  return 0;
}

/* ---- stop-after: from t0 to rest ---------------------------------------------------- */

typedef struct {
  int64_t t0;
  int have_before;
  double speed_t0;               /* speed of the last setpoint at or before t0 */
  /* The stop is the run of non-tracking setpoints that ends at rest: a late plan may
   * arrive after t0 and be followed for a while before the executor gives up on it. */
  int64_t t_run;                 /* first setpoint of the current non-tracking run; 0: none */
  double speed_run, acc_run;     /* speed and |a| there */
  int64_t t_stopping, t_hold;    /* the stop's first setpoint and its first at rest */
  double speed_stopping, acc_stopping;
  int64_t t_track_last;          /* last TRACKING setpoint after t0 */
  double speed_run_last;         /* the current stop run's newest speed */
  int64_t t_replan;              /* first TRACKING setpoint after a stop run; 0: none */
  double speed_replan_from, speed_replan_at;  /* that run's first and last speed */
} stop_acc;

static void stop_visit(const lcm_eventlog_event_t *ev, void *user) {
  stop_acc *s = user;
  nudge_ee_cmd_t m;
  char why[160];
  if (nudge_ee_cmd_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
      ndp_check_ee_cmd(&m, why, sizeof why))
    return;
  if (m.utime <= s->t0) {
    s->have_before = 1;
    s->speed_t0 = norm3(m.v);
    return;
  }
  if (s->t_hold) return;
  if (m.mode == NUDGE_EE_CMD_T_MODE_TRACKING) {
    s->t_track_last = m.utime;
    if (s->t_run && !s->t_replan) {
      s->t_replan = m.utime;
      s->speed_replan_from = s->speed_run;
      s->speed_replan_at = s->speed_run_last;
    }
    s->t_run = 0;
    return;
  }
  s->speed_run_last = norm3(m.v);
  if (!s->t_run) {
    s->t_run = m.utime;
    s->speed_run = norm3(m.v);
    s->acc_run = norm3(m.a);
  }
  if (m.mode == NUDGE_EE_CMD_T_MODE_HOLDING && norm3(m.v) == 0.0) {
    s->t_hold = m.utime;
    s->t_stopping = s->t_run;
    s->speed_stopping = s->speed_run;
    s->acc_stopping = s->acc_run;
  }
}

static int cmd_stop_after(const lc_opts *o) {
  stop_acc s;
  memset(&s, 0, sizeof s);
  s.t0 = o->t0;
  if (for_each(o->log, NDP_CH_EE_CMD, stop_visit, &s)) return 1;
  if (!s.have_before) fail("no setpoint at or before t0 %lld", (long long)o->t0);
  printf("stop_speed_at_t0 %.4f m/s\n", s.speed_t0);
  if (s.t_replan) {
    printf("stop_replanned_after %.1f ms\n", 1e-3 * (double)(s.t_replan - o->t0));
    printf("stop_replanned_speed_from %.4f m/s\n", s.speed_replan_from);
    printf("stop_replanned_speed_at %.4f m/s\n", s.speed_replan_at);
  }
  /* A plan can take over a brake before rest (a restarted planner): with --or-replanned
   * that passes if the brake had slowed the setpoint by then. */
  if (!s.t_hold && o->or_replanned && s.t_replan && s.speed_replan_at < s.speed_replan_from)
    return 0;
  if (!s.t_hold) {
    fail("the executor never came to rest (HOLDING, zero speed) after t0");
    return 0;
  }
  const double t_stop = 1e-3 * (double)(s.t_stopping - o->t0);
  const double t_hold = 1e-3 * (double)(s.t_hold - o->t0);
  /* The fastest possible stop from that speed within the limits: jerk up to a_max, brake
   * at a_max (a lower bound on any brake, the executor's min-snap one included). */
  const double vs = s.speed_stopping, am = o->lim.a_max, jm = o->lim.j_max;
  const double brake_min = vs * jm > am * am ? vs / am + am / jm : 2.0 * sqrt(vs / jm);
  printf("stop_stopping_after %.1f ms\n", t_stop);
  printf("stop_speed_at_stopping %.4f m/s\n", vs);
  printf("stop_acc_at_stopping %.4f m/s^2\n", s.acc_stopping);
  printf("stop_brake_duration %.1f ms\n", t_hold - t_stop);
  printf("stop_brake_min %.1f ms\n", 1e3 * brake_min);
  printf("stop_hold_after %.1f ms\n", t_hold);
  printf("stop_last_tracking_after %.1f ms\n",
         s.t_track_last ? 1e-3 * (double)(s.t_track_last - o->t0) : 0.0);
  if (o->max_ms >= 0 && t_hold > o->max_ms)
    fail("at rest %g ms after t0, allowed %g ms", t_hold, o->max_ms);
  return 0;
}

/* ---- last: newest message of a channel ---------------------------------------------- */

/* The utime of a valid message of one of the nudge channels: it decodes as the channel's
 * type and passes the receivers' validation. 0, or -1 (unknown channel, garbage,
 * refused: a bad-input test logs all of those). */
static int valid_utime(const lcm_eventlog_event_t *ev, int64_t *utime) {
  const char *ch = ev->channel;
  const void *d = ev->data;
  const int n = ev->datalen;
  char why[160];
  int rc = -1;
  if (!strcmp(ch, NDP_CH_PLAN)) {
    nudge_plan_t m;
    if (nudge_plan_t_decode(d, 0, n, &m) >= 0 && !ndp_check_plan(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_EE_CMD)) {
    nudge_ee_cmd_t m;
    if (nudge_ee_cmd_t_decode(d, 0, n, &m) >= 0 && !ndp_check_ee_cmd(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_MOCAP)) {
    nudge_mocap_t m;
    if (nudge_mocap_t_decode(d, 0, n, &m) >= 0 && !ndp_check_mocap(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_ROBOT_STATE)) {
    nudge_robot_state_t m;
    if (nudge_robot_state_t_decode(d, 0, n, &m) >= 0 &&
        !ndp_check_robot_state(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_TASK)) {
    nudge_task_t m;
    if (nudge_task_t_decode(d, 0, n, &m) >= 0 && !ndp_check_task(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_PARAMS)) {
    nudge_params_t m;
    if (nudge_params_t_decode(d, 0, n, &m) >= 0 && !ndp_check_params(&m, why, sizeof why))
      rc = 0, *utime = m.utime;
  } else if (!strcmp(ch, NDP_CH_EPISODE)) {
    nudge_episode_t m;
    if (!ndp_decode_episode(d, n, &m, why, sizeof why)) {
      if (m.utime > 0 && m.task_id >= 0 && m.event >= 0 && m.event < 4) rc = 0, *utime = m.utime;
      nudge_episode_t_decode_cleanup(&m);
    }
  } else if (!strcmp(ch, NDP_CH_STATUS)) {
    nudge_status_t m;
    if (!ndp_decode_status(d, n, &m, why, sizeof why)) {
      if (m.utime > 0) rc = 0, *utime = m.utime;
      nudge_status_t_decode_cleanup(&m);
    }
  }
  return rc;
}

typedef struct {
  int64_t before, after;
  int64_t last, count;
} last_acc;

static void last_visit(const lcm_eventlog_event_t *ev, void *user) {
  last_acc *l = user;
  int64_t t;
  if (valid_utime(ev, &t) || (l->before && t > l->before) || (l->after && t <= l->after))
    return;
  l->count++;
  if (t > l->last) l->last = t;
}

static int cmd_last(const lc_opts *o) {
  last_acc l = {o->before, o->after, 0, 0};
  if (for_each(o->log, o->arg, last_visit, &l)) return 1;
  printf("last_utime %lld us\n", (long long)l.last);
  printf("last_count %lld count\n", (long long)l.count);
  if (!l.count) fail("no %s message in the log", o->arg);
  return 0;
}

/* ---- ee-pos: where the robot was (ROBOT_STATE) within a window ---------------------- */

typedef struct {
  const lc_opts *o;
  int64_t count;
  double first[3], last[3], lo[2], hi[2], travel;
} pos_acc;

static void pos_visit(const lcm_eventlog_event_t *ev, void *user) {
  pos_acc *a = user;
  nudge_robot_state_t m;
  char why[160];
  if (nudge_robot_state_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
      ndp_check_robot_state(&m, why, sizeof why))
    return;
  if ((a->o->from && m.utime < a->o->from) || (a->o->to && m.utime > a->o->to)) return;
  if (!a->count++) {
    memcpy(a->first, m.ee_pos, sizeof a->first);
    for (int k = 0; k < 2; k++) a->lo[k] = a->hi[k] = m.ee_pos[k];
  }
  memcpy(a->last, m.ee_pos, sizeof a->last);
  for (int k = 0; k < 2; k++) {
    if (m.ee_pos[k] < a->lo[k]) a->lo[k] = m.ee_pos[k];
    if (m.ee_pos[k] > a->hi[k]) a->hi[k] = m.ee_pos[k];
  }
  const double d = dist3(m.ee_pos, a->first);
  if (d > a->travel) a->travel = d;
}

static int cmd_ee_pos(const lc_opts *o) {
  pos_acc a;
  memset(&a, 0, sizeof a);
  a.o = o;
  if (for_each(o->log, NDP_CH_ROBOT_STATE, pos_visit, &a)) return 1;
  printf("ee_pos_count %lld count\n", (long long)a.count);
  printf("ee_pos_first_x %.4f m\nee_pos_first_y %.4f m\n", a.first[0], a.first[1]);
  printf("ee_pos_last_x %.4f m\nee_pos_last_y %.4f m\n", a.last[0], a.last[1]);
  printf("ee_pos_x_min %.4f m\nee_pos_x_max %.4f m\n", a.lo[0], a.hi[0]);
  printf("ee_pos_y_min %.4f m\nee_pos_y_max %.4f m\n", a.lo[1], a.hi[1]);
  printf("ee_pos_travel_max %.5f m\n", a.travel);
  if (!a.count) fail("no ROBOT_STATE in the window");
  if (o->max_travel >= 0 && a.travel > o->max_travel)
    fail("the robot moved %.4f m from (%.4f, %.4f) within the window, more than %g m",
         a.travel, a.first[0], a.first[1], o->max_travel);
  return 0;
}

/* ---- sensing: motion capture and robot state of a robot at rest ---------------------- */

#define MAX_SAMPLES 200000

/* Running sums for a mean and standard deviation. */
typedef struct {
  double n, s, ss;
} msum;

static void msum_add(msum *m, double x) { m->n++, m->s += x, m->ss += x * x; }
static double msum_mean(const msum *m) { return m->n > 0 ? m->s / m->n : 0.0; }
static double msum_std(const msum *m) {
  if (m->n < 2) return 0.0;
  const double mu = m->s / m->n;
  return sqrt(fmax(0.0, (m->ss - m->n * mu * mu) / (m->n - 1)));
}

typedef struct {
  const lc_opts *o;
  msum pos[3], ee[3], rot[3];
  double q0[4];            /* the first frame's orientation: rotations are taken from it */
  int64_t count, first_seq, last_seq, gaps, missing, undecodable;
  double *age;             /* ms, one per frame */
  double t_first, t_last;  /* capture times, s */
} noise_acc;

static void noise_visit(const lcm_eventlog_event_t *ev, void *user) {
  noise_acc *a = user;
  nudge_mocap_t m;
  char why[160];
  if (nudge_mocap_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
      ndp_check_mocap(&m, why, sizeof why)) {
    a->undecodable++;
    return;
  }
  if ((a->o->from && m.utime < a->o->from) || (a->o->to && m.utime > a->o->to)) return;
  if (!a->count) {
    memcpy(a->q0, m.obj_quat, sizeof a->q0);
    a->first_seq = m.seq;
    a->t_first = (double)m.utime * 1e-6;
  } else if (m.seq > a->last_seq + 1) {
    a->gaps++;
    a->missing += m.seq - a->last_seq - 1;
  }
  a->last_seq = m.seq;
  a->t_last = (double)m.utime * 1e-6;
  /* The small rotation from the first frame: 2 vec(conj(q0) q), per axis. */
  const double *p = a->q0, *q = m.obj_quat;
  const double sgn = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3] < 0 ? -1.0 : 1.0;
  const double r[3] = {p[0] * q[1] - p[1] * q[0] - p[2] * q[3] + p[3] * q[2],
                       p[0] * q[2] + p[1] * q[3] - p[2] * q[0] - p[3] * q[1],
                       p[0] * q[3] - p[1] * q[2] + p[2] * q[1] - p[3] * q[0]};
  for (int k = 0; k < 3; k++) {
    msum_add(&a->pos[k], m.obj_pos[k]);
    msum_add(&a->ee[k], m.ee_pos[k]);
    msum_add(&a->rot[k], 2.0 * sgn * r[k]);
  }
  if (a->count < MAX_SAMPLES) a->age[a->count] = (double)(ev->timestamp - m.utime) * 1e-3;
  a->count++;
}

static int cmd_mocap_noise(const lc_opts *o) {
  static noise_acc a;
  memset(&a, 0, sizeof a);
  a.o = o;
  static double age[MAX_SAMPLES];
  a.age = age;
  if (for_each(o->log, NDP_CH_MOCAP, noise_visit, &a)) return 1;
  if (a.count < 100) {
    fail("%lld MOCAP frames: too few for noise figures", (long long)a.count);
    return 0;
  }
  const int n = (int)(a.count < MAX_SAMPLES ? a.count : MAX_SAMPLES);
  const double span = a.t_last - a.t_first;
  printf("mocap_frames %lld count\n", (long long)a.count);
  printf("mocap_rate %.1f Hz\n", span > 0 ? (double)(a.last_seq - a.first_seq) / span : 0.0);
  printf("mocap_obj_pos_std %.4f %.4f %.4f mm\n", 1e3 * msum_std(&a.pos[0]),
         1e3 * msum_std(&a.pos[1]), 1e3 * msum_std(&a.pos[2]));
  printf("mocap_ee_pos_std %.4f %.4f %.4f mm\n", 1e3 * msum_std(&a.ee[0]),
         1e3 * msum_std(&a.ee[1]), 1e3 * msum_std(&a.ee[2]));
  printf("mocap_obj_rot_std %.5f %.5f %.5f rad\n", msum_std(&a.rot[0]), msum_std(&a.rot[1]),
         msum_std(&a.rot[2]));
  printf("mocap_obj_pos_mean %.5f %.5f %.5f m\n", msum_mean(&a.pos[0]), msum_mean(&a.pos[1]),
         msum_mean(&a.pos[2]));
  printf("mocap_age_p50 %.3f ms\nmocap_age_p99 %.3f ms\n", nd_quantile(age, n, 0.5),
         nd_quantile(age, n, 0.99));
  const double due = (double)(a.last_seq - a.first_seq + 1);
  printf("mocap_lost_share %.4f of_frames\n", due > 0 ? (double)a.missing / due : 0.0);
  printf("mocap_lost_burst_mean %.2f frames\n", a.gaps ? (double)a.missing / (double)a.gaps : 0.0);
  return 0;
}

typedef struct {
  const lc_opts *o;
  msum pos[3], vel[3], force[3];
  int64_t count, stops, resumes, after_tracking;
  int mode, first_reflex, first_joint;
} rs_acc;

static void rs_visit(const lcm_eventlog_event_t *ev, void *user) {
  rs_acc *a = user;
  nudge_robot_state_t m;
  char why[160];
  if (nudge_robot_state_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
      ndp_check_robot_state(&m, why, sizeof why))
    return;
  if ((a->o->from && m.utime < a->o->from) || (a->o->to && m.utime > a->o->to)) return;
  const int stopped = m.mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED;
  if (a->count && stopped && a->mode != NUDGE_ROBOT_STATE_T_MODE_STOPPED) {
    if (!a->stops++) a->first_reflex = m.reflex, a->first_joint = m.reflex_joint;
  }
  if (a->count && !stopped && a->mode == NUDGE_ROBOT_STATE_T_MODE_STOPPED) a->resumes++;
  if (a->o->after && m.utime > a->o->after && m.mode == NUDGE_ROBOT_STATE_T_MODE_TRACKING)
    a->after_tracking++;
  a->mode = m.mode;
  for (int k = 0; k < 3; k++) {
    msum_add(&a->pos[k], m.ee_pos[k]);
    msum_add(&a->vel[k], m.ee_vel[k]);
    msum_add(&a->force[k], m.ee_force[k]);
  }
  a->count++;
}

static int cmd_robot_state(const lc_opts *o) {
  rs_acc a;
  memset(&a, 0, sizeof a);
  a.o = o;
  if (for_each(o->log, NDP_CH_ROBOT_STATE, rs_visit, &a)) return 1;
  if (!a.count) {
    fail("no ROBOT_STATE in the window");
    return 0;
  }
  printf("robot_states %lld count\n", (long long)a.count);
  printf("robot_pos_std %.5f %.5f %.5f mm\n", 1e3 * msum_std(&a.pos[0]),
         1e3 * msum_std(&a.pos[1]), 1e3 * msum_std(&a.pos[2]));
  printf("robot_vel_std %.5f %.5f %.5f mm/s\n", 1e3 * msum_std(&a.vel[0]),
         1e3 * msum_std(&a.vel[1]), 1e3 * msum_std(&a.vel[2]));
  printf("robot_force_std %.4f %.4f %.4f N\n", msum_std(&a.force[0]), msum_std(&a.force[1]),
         msum_std(&a.force[2]));
  printf("robot_stops %lld count\nrobot_resumes %lld count\n", (long long)a.stops,
         (long long)a.resumes);
  printf("robot_first_reflex %d code\nrobot_first_reflex_joint %d joint\n", a.first_reflex,
         a.first_joint);
  printf("robot_last_mode %d code\n", a.mode);
  if (o->after) printf("robot_tracking_after %lld count\n", (long long)a.after_tracking);
  return 0;
}

/* ---- status: a process's heartbeat counters ----------------------------------------- */

typedef struct {
  const lc_opts *o;
  int found;
  nudge_status_t m;       /* strings not kept: copied below */
  char state[64];
  int64_t beats;
} status_acc;

static void status_visit(const lcm_eventlog_event_t *ev, void *user) {
  status_acc *s = user;
  const lc_opts *o = s->o;
  nudge_status_t m;
  char why[160];
  if (ndp_decode_status(ev->data, ev->datalen, &m, why, sizeof why)) return;
  const int match = !strcmp(m.name, o->arg) && (!o->pid || m.pid == o->pid) &&
                    (!o->state || !strncmp(m.state, o->state, strlen(o->state))) &&
                    (!o->before || m.utime < o->before) && (!o->after || m.utime > o->after);
  /* --after: the first heartbeat after; otherwise the last one (before). */
  if (match && !(o->after && s->found)) {
    s->found = 1;
    s->beats++;
    s->m = m;
    snprintf(s->state, sizeof s->state, "%s", m.state);
    s->m.name = s->m.state = NULL;
  }
  nudge_status_t_decode_cleanup(&m);
}

static int cmd_status(const lc_opts *o) {
  status_acc s;
  memset(&s, 0, sizeof s);
  s.o = o;
  if (for_each(o->log, NDP_CH_STATUS, status_visit, &s)) return 1;
  if (!s.found) {
    fail("no matching STATUS of %s in the log", o->arg);
    return 0;
  }
  printf("pid %d -\n", s.m.pid);
  printf("utime %lld us\n", (long long)s.m.utime);
  printf("state %s -\n", s.state[0] ? s.state : "-");
  printf("received %lld count\n", (long long)s.m.received);
  printf("published %lld count\n", (long long)s.m.published);
  printf("rejected %lld count\n", (long long)s.m.rejected);
  printf("period_p99 %d us\n", s.m.period_p99_us);
  printf("period_max %d us\n", s.m.period_max_us);
  printf("overruns %lld count\n", (long long)s.m.overruns);
  printf("uptime %.1f s\n", s.m.uptime);
  return 0;
}

/* ---- live: is the system moving? (polled on a log still being written) ------------- */

typedef struct {
  int64_t plans, cmds;
  double speed;
  int mode;
} live_acc;

static void live_visit(const lcm_eventlog_event_t *ev, void *user) {
  live_acc *l = user;
  int64_t t;
  if (!strcmp(ev->channel, NDP_CH_PLAN)) {
    if (!valid_utime(ev, &t)) l->plans++;
  } else if (!strcmp(ev->channel, NDP_CH_EE_CMD)) {
    nudge_ee_cmd_t m;
    char why[160];
    if (nudge_ee_cmd_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
        ndp_check_ee_cmd(&m, why, sizeof why))
      return;
    l->cmds++;
    l->speed = norm3(m.v);
    l->mode = m.mode;
  }
}

static int cmd_live(const lc_opts *o) {
  live_acc l = {0, 0, 0.0, -1};
  if (for_each(o->log, NULL, live_visit, &l)) return 1;
  printf("plans %lld count\n", (long long)l.plans);
  printf("ee_cmd_count %lld count\n", (long long)l.cmds);
  printf("ee_speed %.4f m/s\n", l.speed);
  printf("ee_mode %d -\n", l.mode);
  if (o->min_plans >= 0 && l.plans < o->min_plans)
    fail("%lld plans so far, waiting for %d", (long long)l.plans, o->min_plans);
  if (o->min_speed >= 0 && (l.speed < o->min_speed || l.mode != NUDGE_EE_CMD_T_MODE_TRACKING))
    fail("setpoint speed %g m/s, waiting for tracking at %g", l.speed, o->min_speed);
  return 0;
}

/* ---- stale-cmds: did any setpoint move on a stale plan? ----------------------------- */

typedef struct {
  int64_t utime, state_utime;  /* state_utime: the plan's start_utime if it has one */
  double T;
} plan_ref;

typedef struct {
  plan_ref *p;
  int n, cap;
  int oom;
} plan_set;

static void plans_visit(const lcm_eventlog_event_t *ev, void *user) {
  plan_set *s = user;
  nudge_plan_t m;
  char why[160];
  if (nudge_plan_t_decode(ev->data, 0, ev->datalen, &m) < 0 || ndp_check_plan(&m, why, sizeof why))
    return;
  if (s->n == s->cap) {
    const int cap = s->cap ? 2 * s->cap : 4096;
    plan_ref *g = realloc(s->p, sizeof(*g) * cap);
    if (!g) {
      s->oom = 1;
      return;
    }
    s->p = g;
    s->cap = cap;
  }
  s->p[s->n].utime = m.utime;
  /* A plan that names its start was predicted to it from its state. */
  s->p[s->n].state_utime = m.start_utime ? m.start_utime : m.state_utime;
  s->p[s->n].T = m.T;
  s->n++;
}

static int cmp_plan(const void *a, const void *b) {
  const int64_t x = ((const plan_ref *)a)->utime, y = ((const plan_ref *)b)->utime;
  return x < y ? -1 : x > y;
}

typedef struct {
  const lc_opts *o;
  const plan_set *plans;
  int64_t tracking, stale, no_plan, plans_used, unmatched, stale_state;
  int64_t last_ref;              /* plan_utime of the previous tracking setpoint */
  const plan_ref *ref;           /* its PLAN in the log, NULL if not there */
  double age_max_ms, state_age_max_ms;
  int64_t first_stale_utime;
} stale_acc;

static void stale_visit(const lcm_eventlog_event_t *ev, void *user) {
  stale_acc *a = user;
  nudge_ee_cmd_t m;
  char why[160];
  if (nudge_ee_cmd_t_decode(ev->data, 0, ev->datalen, &m) < 0 ||
      ndp_check_ee_cmd(&m, why, sizeof why))
    return;
  /* Braking and holding are what a stale plan must lead to; only tracking moves on a plan. */
  if (m.mode != NUDGE_EE_CMD_T_MODE_TRACKING) return;
  a->tracking++;
  if (m.plan_utime <= 0) {
    a->no_plan++;
    a->stale++;
    if (!a->first_stale_utime) a->first_stale_utime = m.utime;
    return;
  }
  if (m.plan_utime != a->last_ref) {
    a->last_ref = m.plan_utime;
    a->plans_used++;
    const plan_ref key = {m.plan_utime, 0, 0.0};
    a->ref = bsearch(&key, a->plans->p, a->plans->n, sizeof key, cmp_plan);
    if (!a->ref) a->unmatched++;
  }
  const double age_ms = 1e-3 * (double)(m.utime - m.plan_utime);
  if (age_ms > a->age_max_ms) a->age_max_ms = age_ms;
  if (age_ms > 1e3 * a->o->timeout + a->o->slack_ms) {
    a->stale++;
    if (!a->first_stale_utime) a->first_stale_utime = m.utime;
  }
  if (a->ref) {
    /* The executor refuses a plan whose state (or start, when it names one) is older than
     * its segment T on arrival and follows it for the timeout at most: older than that, it
     * moved on a state it had left (a planner that stalled mid-plan, or planned on input
     * it handled late). */
    const double st_ms = 1e-3 * (double)(m.utime - a->ref->state_utime);
    if (st_ms > a->state_age_max_ms) a->state_age_max_ms = st_ms;
    if (st_ms > 1e3 * (a->ref->T + a->o->timeout) + a->o->slack_ms) a->stale_state++;
  }
}

static int cmd_stale_cmds(const lc_opts *o) {
  plan_set plans = {NULL, 0, 0, 0};
  if (for_each(o->log, NDP_CH_PLAN, plans_visit, &plans)) return 1;
  if (plans.oom) {
    fprintf(stderr, PROG ": out of memory for the PLAN messages\n");
    free(plans.p);
    return 1;
  }
  qsort(plans.p, plans.n, sizeof *plans.p, cmp_plan);
  stale_acc a;
  memset(&a, 0, sizeof a);
  a.o = o;
  a.plans = &plans;
  const int rc = for_each(o->log, NDP_CH_EE_CMD, stale_visit, &a);
  free(plans.p);
  if (rc) return 1;
  printf("plans_logged %d count\n", plans.n);
  printf("tracking_commands %lld count\n", (long long)a.tracking);
  printf("tracking_plans %lld count\n", (long long)a.plans_used);
  printf("tracking_plans_not_logged %lld count\n", (long long)a.unmatched);
  printf("tracking_without_plan %lld count\n", (long long)a.no_plan);
  printf("plan_age_max %.3f ms\n", a.age_max_ms);
  printf("plan_state_age_max %.3f ms\n", a.state_age_max_ms);
  printf("stale_commands %lld count\n", (long long)a.stale);
  printf("stale_state_commands %lld count\n", (long long)a.stale_state);
  if (a.stale) printf("first_stale_utime %lld us\n", (long long)a.first_stale_utime);
  if (a.stale)
    fail("%lld tracking setpoints on a plan older than %g s + %g ms (oldest %.1f ms)",
         (long long)a.stale, o->timeout, o->slack_ms, a.age_max_ms);
  if (a.stale_state)
    fail("%lld tracking setpoints on a plan made from a state older than its T + %g s + "
         "%g ms (oldest %.1f ms)", (long long)a.stale_state, o->timeout, o->slack_ms,
         a.state_age_max_ms);
  return 0;
}

/* ---- first-beats: when each process instance was first heard ------------------------ */

#define MAX_BEATS 4096

typedef struct {
  char name[64];
  int32_t pid;
  int64_t first, last;
} beat;

typedef struct {
  beat b[MAX_BEATS];
  int n, full;
} beat_acc;

static void beats_visit(const lcm_eventlog_event_t *ev, void *user) {
  beat_acc *a = user;
  nudge_status_t m;
  char why[160];
  if (ndp_decode_status(ev->data, ev->datalen, &m, why, sizeof why)) return;
  if (m.utime > 0 && m.pid > 0 && m.name[0]) {
    int i = 0;
    while (i < a->n && !(a->b[i].pid == m.pid && !strcmp(a->b[i].name, m.name))) i++;
    if (i == a->n) {
      if (a->n == MAX_BEATS) {
        a->full = 1;
      } else {
        snprintf(a->b[i].name, sizeof a->b[i].name, "%s", m.name);
        a->b[i].pid = m.pid;
        a->b[i].first = a->b[i].last = m.utime;
        a->n++;
      }
    } else {
      if (m.utime < a->b[i].first) a->b[i].first = m.utime;
      if (m.utime > a->b[i].last) a->b[i].last = m.utime;
    }
  }
  nudge_status_t_decode_cleanup(&m);
}

static int cmd_first_beats(const lc_opts *o) {
  static beat_acc a;
  memset(&a, 0, sizeof a);
  if (for_each(o->log, NDP_CH_STATUS, beats_visit, &a)) return 1;
  for (int i = 0; i < a.n; i++)
    printf("first_beat.%s.%d %lld us\n", a.b[i].name, a.b[i].pid, (long long)a.b[i].first);
  printf("beat_instances %d count\n", a.n);
  if (a.full) fail("more than %d process instances: the rest are not listed", MAX_BEATS);
  return 0;
}

/* ---- buffer: the replay buffer against what the recorder committed ------------------ */

static int cmp_i64(const void *a, const void *b) {
  const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
  return x < y ? -1 : x > y;
}

/* Task ids from path, one per line, into a sorted malloc'd array. -1 on error. */
static int load_ids(const char *path, int64_t **out, int *n) {
  FILE *f = fopen(path, "r");
  if (!f) {
    fprintf(stderr, PROG ": cannot open %s\n", path);
    return -1;
  }
  int64_t *ids = NULL;
  int cap = 0, k = 0, rc = 0;
  char line[128], err[200];
  while (fgets(line, sizeof line, f)) {
    line[strcspn(line, "\r\n")] = '\0';
    if (!line[0]) continue;
    uint64_t v;
    if (nd_parse_u64(line, path, &v, err, sizeof err) || v > (uint64_t)INT64_MAX) {
      fprintf(stderr, PROG ": %s: '%s' is not a task id\n", path, line);
      rc = -1;
      break;
    }
    if (k == cap) {
      cap = cap ? 2 * cap : 256;
      int64_t *g = realloc(ids, sizeof(*g) * cap);
      if (!g) {
        rc = -1;
        break;
      }
      ids = g;
    }
    ids[k++] = (int64_t)v;
  }
  fclose(f);
  if (rc) {
    free(ids);
    return -1;
  }
  if (k) qsort(ids, k, sizeof *ids, cmp_i64);
  *out = ids;
  *n = k;
  return 0;
}

static int cmd_buffer(const lc_opts *o) {
  int64_t *committed = NULL, *found = NULL;
  int ncommitted = 0, nfound = 0, cap = 0, rc = 1;
  if (o->committed && load_ids(o->committed, &committed, &ncommitted)) return 1;
  nd_rfile_reader rd;
  char err[512];
  if (nd_rbuf_reader_open(&rd, o->log, err, sizeof err)) {
    fprintf(stderr, PROG ": %s\n", err);
    free(committed);
    return 1;
  }
  int64_t undecodable = 0;
  double start_speed_max = 0.0, start_gap_min = INFINITY, start_off_max = 0.0, start_yaw_max = 0.0;
  nds_scene_cfg sc;
  nds_scene_cfg_default(&sc);
  nd_rfile_tail tail;
  for (;;) {
    nd_rollout r;
    const int64_t at = rd.offset;
    const int k = nd_rbuf_next(&rd, &r, &tail, err, sizeof err);
    if (k == 0) break;
    if (k < 0) {
      if (rd.offset == at) {
        fprintf(stderr, PROG ": %s\n", err);
        goto out;
      }
      /* A sound frame that is no rollout: written by no recorder of ours. */
      fprintf(stderr, PROG ": %s\n", err);
      undecodable++;
      continue;
    }
    if (nfound == cap) {
      cap = cap ? 2 * cap : 256;
      int64_t *g = realloc(found, sizeof(*g) * cap);
      if (!g) {
        nd_rollout_free(&r);
        goto out;
      }
      found = g;
    }
    found[nfound++] = r.task_id;
    /* The object's mean speed over a rollout's first 10 steps: a record starts at rest. */
    if (r.n >= 10) {
      const double *o = nd_rollout_obj(&r, 9);
      const double v = hypot(o[0] - r.obj_pos[0], o[1] - r.obj_pos[1]) / (10 * r.dt);
      if (!(v <= start_speed_max)) start_speed_max = v;
    }
    /* The sphere's gap from the object's sides at the start: released after the last. */
    const nd_release_box box = {.x = r.obj_pos[0], .y = r.obj_pos[1],
                                .yaw = nd_quat_yaw(r.obj_quat),
                                .half = {sc.obj_half[0], sc.obj_half[1]}};
    double n[2];
    const double gap = nd_release_gap(&box, sc.ee_radius, r.ee_pos, n);
    if (!(gap >= start_gap_min)) start_gap_min = gap;
    /* Where the object starts: the origin, when every task places it there. */
    start_off_max = fmax(start_off_max, hypot(r.obj_pos[0], r.obj_pos[1]));
    start_yaw_max = fmax(start_yaw_max, fabs(nd_wrap_angle(box.yaw)));
    nd_rollout_free(&r);
  }
  const int corrupt = (int)undecodable + (tail.status == ND_RFILE_CORRUPT);
  const int torn = tail.status == ND_RFILE_TORN;
  printf("buffer_created %lld us\n", (long long)rd.created_us);
  printf("records_in_file %d count\n", nfound);
  printf("records_corrupt %d count\n", corrupt);
  printf("buffer_tail_torn %d count\n", torn);
  if (tail.status != ND_RFILE_END) fprintf(stderr, PROG ": %s: %s\n", o->log, tail.why);
  if (nfound) qsort(found, nfound, sizeof *found, cmp_i64);
  int dup = 0;
  for (int i = 1; i < nfound; i++) dup += found[i] == found[i - 1];
  printf("records_duplicate %d count\n", dup);
  printf("record_start_speed_max %.4f m/s\n", start_speed_max);
  printf("record_start_gap_min %.4f m\n", nfound ? start_gap_min : 0.0);
  printf("record_start_off_origin_max %.4f m\n", start_off_max);
  printf("record_start_yaw_abs_max %.4f rad\n", start_yaw_max);
  if (o->committed) {
    int missing = 0, dup_c = 0, extra = 0;
    for (int i = 0; i < ncommitted; i++) {
      if (i && committed[i] == committed[i - 1]) {
        dup_c++;
        continue;
      }
      if (!bsearch(&committed[i], found, nfound, sizeof *found, cmp_i64)) {
        if (missing++ < 10)
          fprintf(stderr, PROG ": committed task %lld is not in %s\n", (long long)committed[i],
                  o->log);
      }
    }
    for (int i = 0; i < nfound; i++)
      if (!bsearch(&found[i], committed, ncommitted, sizeof *found, cmp_i64)) extra++;
    printf("records_committed %d count\n", ncommitted - dup_c);
    printf("records_missing %d count\n", missing);
    /* A recorder killed between its commit and its report: in the file, never said. */
    printf("records_unreported %d count\n", extra);
    if (missing) fail("%d committed records are missing from %s", missing, o->log);
    if (dup_c) fail("%d task ids reported committed twice", dup_c);
  }
  if (corrupt) fail("%s: %d corrupt record(s)", o->log, corrupt);
  if (torn && !o->allow_torn) fail("%s ends in a torn record", o->log);
  if (dup) fail("%d records appear twice in %s", dup, o->log);
  rc = 0;
out:
  nd_rfile_reader_close(&rd);
  free(committed);
  free(found);
  return rc;
}

/* ---- history: the adapter's parameter history, entry by entry ----------------------- */

static int cmd_history(const lc_opts *o) {
  char err[512];
  int64_t buf_created = -1, buf_records = -1;
  if (o->buffer) {
    nd_rfile_reader rb;
    if (nd_rbuf_reader_open(&rb, o->buffer, err, sizeof err)) {
      fprintf(stderr, PROG ": %s\n", err);
      return 1;
    }
    buf_created = rb.created_us;
    nd_rfile_record rec;
    int k;
    while ((k = nd_rfile_next(&rb, &rec, NULL, err, sizeof err)) == 1) {
    }
    buf_records = rb.records;
    nd_rfile_reader_close(&rb);
    if (k < 0) {
      fprintf(stderr, PROG ": %s\n", err);
      return 1;
    }
  }
  nd_rfile_reader rd;
  if (nd_rfile_reader_open(&rd, o->log, ND_RFILE_KIND_PARAMS, err, sizeof err)) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  int64_t entries = 0, bad = 0, backwards = 0, gaps = 0, shrinks = 0, other = 0, over = 0;
  int64_t first = 0, last = 0, size_max = 0;
  int32_t prev_size = 0;
  nd_rfile_tail tail;
  int k;
  for (;;) {
    nd_rfile_record rec;
    k = nd_rfile_next(&rd, &rec, &tail, err, sizeof err);
    if (k <= 0) break;
    nd_history_entry e;
    char why[200];
    if (rec.kind != ND_RFILE_KIND_PARAMS || nd_history_decode(&e, rec.data, rec.len, why, sizeof why)) {
      if (bad++ < 5)
        fprintf(stderr, PROG ": %s: bad entry at offset %lld\n", o->log, (long long)rec.offset);
      continue;
    }
    if (entries == 0) {
      first = e.version;
    } else {
      if (e.version <= last) backwards++;
      else if (e.version != last + 1) gaps++;
      if (e.buffer_size < prev_size) shrinks++;
    }
    if (o->buffer && e.buffer_created != buf_created) other++;
    if (o->buffer && e.buffer_size > buf_records) over++;
    if (e.buffer_size > size_max) size_max = e.buffer_size;
    last = e.version;
    prev_size = e.buffer_size;
    entries++;
  }
  nd_rfile_reader_close(&rd);
  if (k < 0) {
    fprintf(stderr, PROG ": %s\n", err);
    return 1;
  }
  const int corrupt = (int)bad + (tail.status == ND_RFILE_CORRUPT);
  printf("history_entries %lld count\n", (long long)entries);
  printf("history_corrupt %d count\n", corrupt);
  printf("history_tail_torn %d count\n", tail.status == ND_RFILE_TORN);
  printf("history_version_first %lld -\n", (long long)first);
  printf("history_version_last %lld -\n", (long long)last);
  printf("history_version_backwards %lld count\n", (long long)backwards);
  printf("history_version_gaps %lld count\n", (long long)gaps);
  printf("history_size_shrinks %lld count\n", (long long)shrinks);
  printf("history_size_max %lld count\n", (long long)size_max);
  if (tail.status != ND_RFILE_END) fprintf(stderr, PROG ": %s: %s\n", o->log, tail.why);
  if (o->buffer) {
    printf("history_other_buffer %lld count\n", (long long)other);
    printf("history_beyond_buffer %lld count\n", (long long)over);
    if (other) fail("%lld entries were fitted on another buffer than %s", (long long)other, o->buffer);
    if (over)
      fail("%lld entries were fitted on more rollouts than %s holds (%lld)", (long long)over,
           o->buffer, (long long)buf_records);
  }
  if (corrupt) fail("%s: %d corrupt entr%s", o->log, corrupt, corrupt == 1 ? "y" : "ies");
  if (tail.status == ND_RFILE_TORN && !o->allow_torn) fail("%s ends in a torn entry", o->log);
  if (backwards) fail("versions went backwards %lld times", (long long)backwards);
  if (gaps) fail("versions skipped %lld times (a fit not kept)", (long long)gaps);
  if (shrinks) fail("the buffer size fitted on shrank %lld times", (long long)shrinks);
  return 0;
}

/* ---- command line ------------------------------------------------------------------- */

static void usage(FILE *f) {
  const nd_exec_cfg d = nd_exec_cfg_default();
  fprintf(f,
          "usage: " PROG " COMMAND LOG [ARG] [options]\n"
          "Figures and checks from an lcm-logger log of a nudge run (or its replay buffer\n"
          "and parameter history), as 'name value unit' lines. Exit 1 when an asked-for\n"
          "check fails (named on stderr), 2 on bad usage.\n\n"
          "  episodes LOG     counts of EPISODE start/success/timeout/rejected, each task's end\n"
          "      --min-start N, --min-success N, --min-end N, --first-success\n"
          "  ee-cmd LOG       EE_CMD count, gaps (between setpoints sent one after the\n"
          "                   other: seq + 1; setpoints lost by the logger are counted\n"
          "                   apart), and the largest steps |dp|, |dv|, |da|\n"
          "                   between consecutive setpoints relative to v_max dt, a_max dt,\n"
          "                   j_max dt, overall and across plan switches; fails if a step\n"
          "                   exceeds the limits, a setpoint exceeds v_max or a_max\n"
          "      --max-gap-ms G     fail on a gap beyond G ms\n"
          "      --v-max V, --a-max A, --j-max J  limits (default %g, %g, %g: nd_exec's)\n"
          "      --slack-us S       added to each dt for clock-read jitter (default 50)\n"
          "      --from-utime U, --to-utime U     window\n"
          "  stop-after LOG --t0-utime U   time from U until the setpoints are at rest\n"
          "                   (HOLDING, zero speed); when the stop began (the run of\n"
          "                   non-tracking setpoints ending at rest), speeds, brake time\n"
          "      --max-ms M         fail if at rest later than M ms after U\n"
          "      --or-replanned     also pass if a plan took over a brake that had slowed\n"
          "  last LOG CHANNEL newest utime and count of CHANNEL's valid messages\n"
          "      --before-utime U (at or before U), --after-utime U (after U)\n"
          "  status LOG NAME  heartbeat counters of process NAME: the last one, or\n"
          "      --before-utime U (last before U), --after-utime U (first after U), --pid P,\n"
          "      --state S (only heartbeats whose state begins with S)\n"
          "  mocap-noise LOG  MOCAP of a scene at rest: frames, rate, standard deviations of\n"
          "                   the object's position (mm) and rotation (rad) per axis and of\n"
          "                   the sphere's position, age at the logger (p50, p99), frames\n"
          "                   lost (seq gaps) and their mean burst\n"
          "      --from-utime U, --to-utime U     window\n"
          "  robot-state LOG  ROBOT_STATE: standard deviations of position, velocity and\n"
          "                   force per axis; reflex stops and resumes (mode changes), the\n"
          "                   first stop's reflex and joint, the last mode\n"
          "      --from-utime U, --to-utime U     window\n"
          "      --after-utime U    also count TRACKING states after U\n"
          "  ee-pos LOG       the robot's positions (ROBOT_STATE): count, first, last, x and\n"
          "                   y range, farthest from the first\n"
          "      --from-utime U, --to-utime U     window\n"
          "      --max-travel M     fail if a position lies farther than M m from the first\n"
          "  live LOG         plans so far, newest setpoint's speed and mode\n"
          "      --min-plans N, --min-speed S (and tracking)\n"
          "  stale-cmds LOG --timeout S   every TRACKING setpoint must follow a plan at most\n"
          "                   S (+ slack) old (EE_CMD.utime - plan_utime), made from a state\n"
          "                   at most the plan's T + S (+ slack) old (if the PLAN is in the\n"
          "                   log); fails if one does not, or tracks with no plan\n"
          "      --slack-ms M       allowance on S (default 2: the loop's period and clocks)\n"
          "  first-beats LOG  'first_beat.NAME.PID UTIME us' for every process instance\n"
          "  buffer FILE      records of a replay buffer (core reader): count, corrupt, torn\n"
          "                   tail, duplicates; fails on corrupt, duplicate or torn\n"
          "      --committed IDS    task ids the recorder reported committed, one a line:\n"
          "                         fails if one is not in FILE\n"
          "      --allow-torn       a torn last record is no failure (writer killed mid-append)\n"
          "  history FILE     the adapter's parameter history entry by entry: fails on a\n"
          "                   corrupt entry, versions not +1 each, a shrinking fitted size\n"
          "      --buffer BUF       and on entries fitted on another buffer or on more\n"
          "                         rollouts than BUF holds\n"
          "      --allow-torn       as for buffer\n",
          d.v_max, d.a_max, d.j_max);
}

static int bad_arg(const char *msg) {
  fprintf(stderr, PROG ": %s\n", msg);
  usage(stderr);
  return 2;
}

static int parse_utime(const char *v, const char *what, int64_t *out, char *err, int n) {
  uint64_t u;
  if (nd_parse_u64(v, what, &u, err, n)) return -1;
  if (u == 0 || u > (uint64_t)INT64_MAX) {
    snprintf(err, n, "%s: %s is not a utime (us)", what, v);
    return -1;
  }
  *out = (int64_t)u;
  return 0;
}

static int parse_args(int argc, char **argv, lc_opts *o) {
  char err[256];
  memset(o, 0, sizeof *o);
  o->min_start = o->min_success = o->min_end = o->min_plans = -1;
  o->max_gap_ms = o->max_ms = o->min_speed = o->max_travel = -1.0;
  o->slack_us = 50.0;
  o->slack_ms = 2.0;
  o->lim = nd_exec_cfg_default();
  if (argc >= 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"))) {
    usage(stdout);
    return 0;
  }
  if (argc < 3) return bad_arg("need a COMMAND and a LOG");
  o->cmd = argv[1];
  o->log = argv[2];
  int i = 3;
  const int needs_arg = !strcmp(o->cmd, "status") || !strcmp(o->cmd, "last");
  if (strcmp(o->cmd, "episodes") && strcmp(o->cmd, "ee-cmd") && strcmp(o->cmd, "stop-after") &&
      strcmp(o->cmd, "live") && strcmp(o->cmd, "stale-cmds") && strcmp(o->cmd, "first-beats") &&
      strcmp(o->cmd, "buffer") && strcmp(o->cmd, "history") && strcmp(o->cmd, "ee-pos") &&
      strcmp(o->cmd, "mocap-noise") && strcmp(o->cmd, "robot-state") &&
      !needs_arg) {
    snprintf(err, sizeof err, "unknown command '%s'", o->cmd);
    return bad_arg(err);
  }
  if (needs_arg) {
    if (argc < 4 || argv[3][0] == '-') return bad_arg("status and last need a NAME / CHANNEL");
    o->arg = argv[i++];
  }
  for (; i < argc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--first-success")) {
      o->first_success = 1;
      continue;
    }
    if (!strcmp(a, "--allow-torn")) {
      o->allow_torn = 1;
      continue;
    }
    if (!strcmp(a, "--or-replanned")) {
      o->or_replanned = 1;
      continue;
    }
    if (i + 1 >= argc) {
      snprintf(err, sizeof err, "%s needs a value (or is unknown)", a);
      return bad_arg(err);
    }
    const char *v = argv[++i];
    int rc = 0;
    if (!strcmp(a, "--min-start")) rc = nd_parse_int(v, a, 0, 1000000, &o->min_start, err, sizeof err);
    else if (!strcmp(a, "--min-success")) rc = nd_parse_int(v, a, 0, 1000000, &o->min_success, err, sizeof err);
    else if (!strcmp(a, "--min-end")) rc = nd_parse_int(v, a, 0, 1000000, &o->min_end, err, sizeof err);
    else if (!strcmp(a, "--min-plans")) rc = nd_parse_int(v, a, 0, 100000000, &o->min_plans, err, sizeof err);
    else if (!strcmp(a, "--max-gap-ms")) rc = nd_parse_double(v, a, 0.0, 1e6, &o->max_gap_ms, err, sizeof err);
    else if (!strcmp(a, "--max-ms")) rc = nd_parse_double(v, a, 0.0, 1e7, &o->max_ms, err, sizeof err);
    else if (!strcmp(a, "--max-travel")) rc = nd_parse_double(v, a, 0.0, 100.0, &o->max_travel, err, sizeof err);
    else if (!strcmp(a, "--min-speed")) rc = nd_parse_double(v, a, 0.0, 100.0, &o->min_speed, err, sizeof err);
    else if (!strcmp(a, "--timeout")) rc = nd_parse_double(v, a, 1e-4, 60.0, &o->timeout, err, sizeof err);
    else if (!strcmp(a, "--slack-ms")) rc = nd_parse_double(v, a, 0.0, 1e4, &o->slack_ms, err, sizeof err);
    else if (!strcmp(a, "--committed")) o->committed = v;
    else if (!strcmp(a, "--buffer")) o->buffer = v;
    else if (!strcmp(a, "--state")) o->state = v;
    else if (!strcmp(a, "--slack-us")) rc = nd_parse_double(v, a, 0.0, 1e6, &o->slack_us, err, sizeof err);
    else if (!strcmp(a, "--v-max")) rc = nd_parse_double(v, a, 1e-6, 1e3, &o->lim.v_max, err, sizeof err);
    else if (!strcmp(a, "--a-max")) rc = nd_parse_double(v, a, 1e-6, 1e6, &o->lim.a_max, err, sizeof err);
    else if (!strcmp(a, "--j-max")) rc = nd_parse_double(v, a, 1e-6, 1e9, &o->lim.j_max, err, sizeof err);
    else if (!strcmp(a, "--t0-utime")) rc = parse_utime(v, a, &o->t0, err, sizeof err);
    else if (!strcmp(a, "--before-utime")) rc = parse_utime(v, a, &o->before, err, sizeof err);
    else if (!strcmp(a, "--after-utime")) rc = parse_utime(v, a, &o->after, err, sizeof err);
    else if (!strcmp(a, "--from-utime")) rc = parse_utime(v, a, &o->from, err, sizeof err);
    else if (!strcmp(a, "--to-utime")) rc = parse_utime(v, a, &o->to, err, sizeof err);
    else if (!strcmp(a, "--pid")) {
      int p;
      rc = nd_parse_int(v, a, 1, 1 << 30, &p, err, sizeof err);
      o->pid = p;
    } else {
      snprintf(err, sizeof err, "unknown option '%s' for %s", a, o->cmd);
      return bad_arg(err);
    }
    if (rc) return bad_arg(err);
  }
  if (!strcmp(o->cmd, "stop-after") && !o->t0) return bad_arg("stop-after needs --t0-utime");
  if (!strcmp(o->cmd, "stale-cmds") && !(o->timeout > 0.0))
    return bad_arg("stale-cmds needs --timeout (the executor's)");
  if (o->before && o->after && !strcmp(o->cmd, "status"))
    return bad_arg("status: --before-utime and --after-utime exclude each other");
  return -1;
}

int main(int argc, char **argv) {
  static lc_opts o;
  const int prc = parse_args(argc, argv, &o);
  if (prc >= 0) return prc;
  int rc;
  if (!strcmp(o.cmd, "episodes")) rc = cmd_episodes(&o);
  else if (!strcmp(o.cmd, "ee-cmd")) rc = cmd_ee_cmd(&o);
  else if (!strcmp(o.cmd, "stop-after")) rc = cmd_stop_after(&o);
  else if (!strcmp(o.cmd, "last")) rc = cmd_last(&o);
  else if (!strcmp(o.cmd, "ee-pos")) rc = cmd_ee_pos(&o);
  else if (!strcmp(o.cmd, "mocap-noise")) rc = cmd_mocap_noise(&o);
  else if (!strcmp(o.cmd, "robot-state")) rc = cmd_robot_state(&o);
  else if (!strcmp(o.cmd, "status")) rc = cmd_status(&o);
  else if (!strcmp(o.cmd, "stale-cmds")) rc = cmd_stale_cmds(&o);
  else if (!strcmp(o.cmd, "first-beats")) rc = cmd_first_beats(&o);
  else if (!strcmp(o.cmd, "buffer")) rc = cmd_buffer(&o);
  else if (!strcmp(o.cmd, "history")) rc = cmd_history(&o);
  else rc = cmd_live(&o);
  return rc ? rc : failures ? 1 : 0;
}
