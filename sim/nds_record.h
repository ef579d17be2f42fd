/* nds_record: recording an episode (nds_episode_run) into an nd_rollout for the replay
 * buffer.
 *
 * The arrays are allocated once, for the longest episode the recorder will see (capacity
 * from tau / dt); the per-step hook only writes into them. A recording holds the start
 * state (nds_replay_start_put), per world step the force the controller applied (u, a
 * force record), the setpoint it tracked (sp) and the observation after the step
 * (nds_replay_observe), and the task's metadata. Replayed in the recording model it is
 * exact in FORCE and SETPOINT mode (nds_replay.h).
 *
 *   nds_record rec;
 *   nds_record_init(&rec, tau, world.m->opt.timestep, ...);
 *   nds_record_begin(&rec, &world, &start, task_id, utime, &goal, theta, ...);
 *   nds_episode_run(..., &start, &goal, nds_record_hook, &rec, &out, ...);
 *   nds_record_finish(&rec, out.reached ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT, ...);
 *   nd_rbuf_append(&w, &rec.r, ...);
 */
#ifndef NDS_RECORD_H
#define NDS_RECORD_H

#include <stdint.h>

#include "nd_cost.h"
#include "nd_rollout.h"
#include "nds_state.h"

typedef struct {
  nd_rollout r;    /* the recording; r.n = steps recorded so far (arrays hold cap) */
  int cap;         /* steps the arrays hold */
  int dropped;     /* steps past cap, not recorded (finish then fails) */
  int open;        /* between begin and finish */
} nds_record;

/* Allocate for episodes of up to tau seconds at world step dt: the episode steps while
 * t = k dt <= tau, so floor(tau / dt) + 1 steps, plus one for rounding. Return 0, or -1
 * with a message (tau, dt not positive, too many steps, no memory). */
int nds_record_init(nds_record *rec, double tau, double dt, char *err, int errlen);

/* Free the arrays; rec is zeroed. Safe on a zeroed or freed recorder. */
void nds_record_free(nds_record *rec);

/* Start a recording of a task run in world from start: metadata (task id, start time in
 * microseconds since the epoch, goal, the theta the planner uses, dt = world's timestep,
 * control = force), no steps yet. Return 0, or -1 if world's timestep is not the dt of
 * init (a recording of another rate would not replay). */
int nds_record_begin(nds_record *rec, const nds_model *world, const nds_state *start,
                     int64_t task_id, int64_t utime, const nd_goal *goal,
                     const double theta[ND_NTHETA], char *err, int errlen);

/* The nds_episode_hook: ctx is the nds_record. Appends one step; allocates nothing. */
void nds_record_hook(void *ctx, const nds_model *world, const mjData *d, const double sp[2][4],
                     const double force[2]);

/* End the recording with outcome (ND_OUTCOME_*). Return 0 with rec->r a valid rollout
 * (nd_rollout_check), or -1 with a message: no step, steps dropped past the capacity,
 * a bad outcome, a value not finite. rec->r stays valid until the next begin. */
int nds_record_finish(nds_record *rec, int outcome, char *err, int errlen);

#endif
