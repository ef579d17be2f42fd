/* overlay: the text over the frame (view.h): the task and its error against eps, plans/s
 * and the newest plan, theta, the last task event (top left), each process's heartbeat
 * (top right). Ages and rates are in view time, so a log's frames are reproducible. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "nd_cost.h"
#include "nd_math.h"
#include "view.h"

#define SILENT_S 3.0      /* a heartbeat older than this (1 Hz nominal) is shown as silent */
#define REASON_SHOWN 48   /* characters of an EPISODE reason shown */

typedef struct {
  char *buf;
  int cap, n;
} text;

static void put(text *t, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void put(text *t, const char *fmt, ...) {
  if (t->n >= t->cap - 1) return;
  va_list ap;
  va_start(ap, fmt);
  const int k = vsnprintf(t->buf + t->n, (size_t)(t->cap - t->n), fmt, ap);
  va_end(ap);
  if (k > 0) t->n = t->n + k < t->cap - 1 ? t->n + k : t->cap - 1;
}

static const char *event_name(int e) {
  static const char *const names[] = {"started", "succeeded", "timed out", "rejected",
                                      "stopped by a reflex"};
  return e >= 0 && e <= NUDGE_EPISODE_T_EVENT_STOPPED ? names[e] : "?";
}

static void left_block(const view_inputs *in, int64_t now_us, text *k, text *v) {
  const nudge_task_t *t = &in->task;
  put(k, "task");
  if (in->have_task)
    put(v, "#%lld  goal (%+.3f, %+.3f) m  %+.0f deg  eps %g", (long long)t->task_id,
        t->goal_x, t->goal_y, t->goal_yaw * 180.0 / ND_PI, t->eps);
  else
    put(v, "none yet");
  put(k, "\nerror");
  if (in->have_task && in->have_mocap) {
    const nd_cost_weights w = nd_cost_weights_default();
    const nd_goal g = {t->goal_x, t->goal_y, t->goal_yaw, t->eps, t->time_limit, 0};
    const double e = nd_task_error(&w, &g, in->mocap.obj_pos, nd_quat_yaw(in->mocap.obj_quat));
    put(v, "\n%.4f  %s eps %g  (L_pos + %g L_rot)", e, e < t->eps ? "<" : ">=", t->eps, w.w_rot);
  } else {
    put(v, "\n%s", in->have_mocap ? "-" : "no MOCAP yet");
  }
  put(k, "\nplans/s");
  put(v, "\n%.1f", view_inputs_plan_rate(in, now_us));
  if (in->have_plan)
    put(v, "  #%lld: M %d, T %.2f s, cost %.4g, %.0f ms", (long long)in->plan.plan_id,
        in->plan.M, in->plan.T, in->plan.cost, in->plan.plan_ms);
  put(k, "\ntheta");
  if (in->have_params) {
    const double *th = in->params.theta_mean;
    put(v, "\nv%lld: slide %.3g  torsion %.3g  roll %.3g  mass %.3g kg",
        (long long)in->params.version, th[0], th[1], th[2], th[3]);
    /* The box's entries only when a fit moved them from the model's box. */
    if (th[ND_TH_BOX_SCALE] != 1 || th[ND_TH_COM_X] != 0 || th[ND_TH_COM_Y] != 0)
      put(v, "  box x%.3g, COM %+.1f %+.1f mm", th[ND_TH_BOX_SCALE], 1e3 * th[ND_TH_COM_X],
          1e3 * th[ND_TH_COM_Y]);
  } else {
    put(v, "\nno PARAMS yet");
  }
  if (in->have_episode) {
    put(k, "\nepisode");
    put(v, "\ntask #%lld %s at %.2f s, error %.4f", (long long)in->ep_task_id,
        event_name(in->ep_event), in->ep_time, in->ep_error);
    /* On a row of its own, cut short: it must not run under the heartbeats' column. */
    if (in->ep_reason[0]) {
      const int cut = (int)strlen(in->ep_reason) > REASON_SHOWN;
      put(k, "\nwhy");
      put(v, "\n%.*s%s", cut ? REASON_SHOWN - 3 : REASON_SHOWN, in->ep_reason, cut ? "..." : "");
    }
  }
}

static void right_block(const view_inputs *in, int64_t now_us, text *k, text *v) {
  /* By name, so the rows keep their places whatever order the heartbeats came in. */
  int order[VIEW_MAX_PROCS];
  for (int i = 0; i < in->nprocs; i++) {
    int j = i;
    for (; j > 0 && strcmp(in->procs[order[j - 1]].name, in->procs[i].name) > 0; j--)
      order[j] = order[j - 1];
    order[j] = i;
  }
  for (int r = 0; r < in->nprocs; r++) {
    const view_beat *p = &in->procs[order[r]];
    const double age = 1e-6 * (double)(now_us - p->utime);
    put(k, "%s%s", r ? "\n" : "", p->name);
    put(v, "%s%s", r ? "\n" : "", p->state[0] ? p->state : "-");
    if (age > SILENT_S) put(v, ", silent %.0f s", age);
    else put(v, ", %.1f s ago", age > 0.0 ? age : 0.0);
    if (p->rejected) put(v, ", %lld rejected", (long long)p->rejected);
  }
}

/* One block of text: from the atlas when there is one. */
static void block(const view_text *t, const mjrContext *con, mjrRect vp, int right,
                  const char *k, const char *v) {
  if (t->tex) view_text_block(t, vp, right, k, v);
  else mjr_overlay(mjFONT_NORMAL, right ? mjGRID_TOPRIGHT : mjGRID_TOPLEFT, vp, k, v, con);
}

void view_overlay(const view_inputs *in, int64_t now_us, mjrRect vp, const mjrContext *con,
                  const view_text *t) {
  char kb[1024], vb[2048];
  text k = {kb, sizeof kb, 0}, v = {vb, sizeof vb, 0};
  kb[0] = vb[0] = '\0';
  left_block(in, now_us, &k, &v);
  block(t, con, vp, 0, kb, vb);
  if (!in->nprocs) return;
  k.n = v.n = 0;
  kb[0] = vb[0] = '\0';
  right_block(in, now_us, &k, &v);
  block(t, con, vp, 1, kb, vb);
}
