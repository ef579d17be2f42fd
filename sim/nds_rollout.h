/* nds_rollout: one rollout of a keypoint sequence, and batches of them on a pool.
 *
 * A rollout starts the model at state s0 with the executor's setpoint state sp0, chains
 * M minimum-snap segments of duration T through the keypoints (x, y, vx, vy), drives the
 * sphere along them with the tracking controller and steps MuJoCo for M*T seconds. */
#ifndef NDS_ROLLOUT_H
#define NDS_ROLLOUT_H

#include "nd_pool.h"
#include "nd_snap.h"
#include "nds_ctrl.h"
#include "nds_model.h"
#include "nds_state.h"

/* Object poses a rollout samples along its horizon, after the step that reaches its (k + 1)
 * / NDS_ROLLOUT_NS (the first step, for a horizon of fewer steps). */
#define NDS_ROLLOUT_NS 8

typedef struct {
  double obj_at[NDS_ROLLOUT_NS][3]; /* object (x, y, yaw) at (k + 1) / NS of the horizon */
  double obj_xy[2];     /* final object position */
  double obj_yaw;       /* final object yaw */
  double ee_xy[2];      /* final sphere position */
  double ee_at[NDS_ROLLOUT_NS][2];  /* sphere (x, y) at the obj_at samples */
  double acc_sq_mean;   /* L_acc: mean over steps of |setpoint acceleration|^2 */
  double v_peak;        /* peak setpoint speed over the rollout, m/s */
  double a_peak;        /* peak setpoint acceleration magnitude, m/s^2 */
  int diverged;         /* non-finite state or a MuJoCo instability warning */
  int steps, skipped;   /* steps, and of those skipped in free flight (nds_rollout_ff) */
} nds_rollout_out;

/* Run one rollout on d (any prior content; the result depends only on the arguments).
 * keys holds M * 4 values; M * T / timestep rounds to the step count. Never fails: bad
 * input or a divergence (non-finite state, any MuJoCo warning) gives out->diverged = 1
 * with the other fields zero. d is scratch: its warning counters are preset so MuJoCo
 * does not print for the divergences reported here. Allocates nothing. */
void nds_rollout(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl,
                 const nds_state *s0, const double sp0[2][4], const double *keys, int M,
                 double T, nds_rollout_out *out);

/* nds_rollout with free flight (free_flight 1): while the sphere is far from an object
 * settled at rest, the steps skip MuJoCo and integrate the sphere alone as MuJoCo's Euler
 * step would (v += dt f / m, x += dt v), the object held still: nothing can touch it then,
 * and the contact solver is most of a step's cost. Outcomes agree with free_flight 0 to a
 * few micrometres (test_rollout); nudge-bench prints the time saved. out->skipped counts
 * the steps that skipped. */
void nds_rollout_ff(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl,
                    const nds_state *s0, const double sp0[2][4], const double *keys, int M,
                    double T, int free_flight, nds_rollout_out *out);

/* Advance s0 by n steps of nm with the sphere tracking setpoint sp[i] through step i, as a
 * rollout does, into s1: the state n steps ahead if the executor's trajectory sp is
 * followed. Return 0, or -1 with a message (non-finite input, divergence). d is scratch.
 * Allocates nothing. */
int nds_predict(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl, const nds_state *s0,
                const double (*sp)[2][4], int n, nds_state *s1, char *err, int errlen);

/* Per-worker MuJoCo copies for parallel rollouts: each worker owns an nds_model copy
 * (so theta can differ per task) and one mjData, allocated once. */
typedef struct nds_batch nds_batch;

/* One model copy and mjData per worker of pool. NULL and a message on error. */
nds_batch *nds_batch_create(const nds_model *proto, nd_pool *pool, char *err, int errlen);
void nds_batch_free(nds_batch *b);

nd_pool *nds_batch_pool(nds_batch *b);
nds_model *nds_batch_model(nds_batch *b, int worker);
mjData *nds_batch_data(nds_batch *b, int worker);

/* Apply theta to every worker's model. Return 0, or -1 with a message (models unchanged). */
int nds_batch_set_theta(nds_batch *b, const double theta[ND_NTHETA], char *err, int errlen);

/* Rollouts of b in free flight (nds_rollout_ff) from now on: 1 on, 0 off (the default). */
void nds_batch_set_free_flight(nds_batch *b, int on);

/* Run n rollouts (keys: n * M * 4) from one state in parallel; out has n entries. */
void nds_batch_rollouts(nds_batch *b, const nds_ctrl_cfg *ctrl, const nds_state *s0,
                        const double sp0[2][4], const double *keys, int n, int M, double T,
                        nds_rollout_out *out);

#endif
