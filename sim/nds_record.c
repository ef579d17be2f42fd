/* nds_record: a preallocated episode recorder. */
#include "nds_record.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nds_replay.h"

/* dt of begin and of init may differ by this much (relative): the same timestep written
 * in two places, not two rates. */
#define DT_TOL 1e-12

int nds_record_init(nds_record *rec, double tau, double dt, char *err, int errlen) {
  memset(rec, 0, sizeof(*rec));
  if (!(isfinite(tau) && tau > 0 && isfinite(dt) && dt > 0)) {
    snprintf(err, errlen, "recorder: tau = %g s and dt = %g s must be finite and > 0", tau, dt);
    return -1;
  }
  const double steps = floor(tau / dt) + 2;
  if (steps > ND_ROLLOUT_MAX_STEPS) {
    snprintf(err, errlen, "recorder: tau / dt = %.0f steps exceeds the record limit %d",
             steps, ND_ROLLOUT_MAX_STEPS);
    return -1;
  }
  if (nd_rollout_alloc(&rec->r, (int)steps)) {
    snprintf(err, errlen, "recorder: out of memory for %.0f steps", steps);
    return -1;
  }
  rec->cap = (int)steps;
  rec->r.dt = dt;
  rec->r.n = 0;
  return 0;
}

void nds_record_free(nds_record *rec) {
  nd_rollout_free(&rec->r);
  memset(rec, 0, sizeof(*rec));
}

int nds_record_begin(nds_record *rec, const nds_model *world, const nds_state *start,
                     int64_t task_id, int64_t utime, const nd_goal *goal,
                     const double theta[ND_NTHETA], char *err, int errlen) {
  if (rec->cap < 1) {
    snprintf(err, errlen, "recorder: not initialised");
    return -1;
  }
  const double dt = world->m->opt.timestep;
  if (fabs(dt - rec->r.dt) > DT_TOL * rec->r.dt) {
    snprintf(err, errlen, "recorder: world timestep %g s, recorder sized for %g s", dt,
             rec->r.dt);
    return -1;
  }
  nd_rollout *r = &rec->r;
  r->task_id = task_id;
  r->utime = utime;
  r->goal[0] = goal->x;
  r->goal[1] = goal->y;
  r->goal[2] = goal->yaw;
  memcpy(r->theta, theta, sizeof(r->theta));
  r->outcome = ND_OUTCOME_ABORTED; /* until finish says otherwise */
  r->control = ND_CTRL_FORCE;
  r->dt = dt;
  nds_replay_start_put(r, start);
  r->n = 0;
  rec->dropped = 0;
  rec->open = 1;
  return 0;
}

void nds_record_hook(void *ctx, const nds_model *world, const mjData *d, const double sp[2][4],
                     const double force[2]) {
  nds_record *rec = ctx;
  nd_rollout *r = &rec->r;
  if (!rec->open) return;
  if (r->n >= rec->cap) {
    rec->dropped++;
    return;
  }
  const int k = r->n;
  r->u[2 * k] = force[0];
  r->u[2 * k + 1] = force[1];
  nds_replay_sp_put(r->sp + 6 * k, sp);
  nds_replay_observe(world, d, nd_rollout_obj(r, k), r->ee + 2 * k);
  r->n = k + 1;
}

int nds_record_finish(nds_record *rec, int outcome, char *err, int errlen) {
  if (!rec->open) {
    snprintf(err, errlen, "recorder: finish without begin");
    return -1;
  }
  rec->open = 0;
  if (rec->dropped) {
    snprintf(err, errlen, "recorder: the episode ran %d steps, the recorder holds %d",
             rec->r.n + rec->dropped, rec->cap);
    return -1;
  }
  rec->r.outcome = outcome;
  return nd_rollout_check(&rec->r, err, errlen);
}
