/* nds_replay: replaying a recorded rollout in the model, and how far the model strays.
 *
 * The replay starts the model in the rollout's initial state and applies its recorded
 * controls open-loop: in force mode u is the force on the sphere's two dofs, in velocity
 * mode the sphere tracks u with the robot's velocity controller (nds_ctrl_vel). After
 * each step the model's object (x, y, yaw) and sphere (x, y) are compared with what was
 * observed, giving one rollout's terms of the adaptation loss (DESIGN.md sec. 4):
 *
 *   L = L_pos,o + k1 L_pos,ee + k2 L_rot,o, each term 1/T sum over the T compared steps.
 *
 * A model whose timestep is k times the record's (k a whole number) replays k recorded
 * steps per model step with their mean control and compares every k-th observation. */
#ifndef NDS_REPLAY_H
#define NDS_REPLAY_H

#include "nd_rollout.h"
#include "nds_ctrl.h"
#include "nds_state.h"

/* What a diverged replay scores in each term (m^2 for the positions, rad for yaw): far
 * above anything a replay that stays finite on a table can reach (a 1 km mean error), yet
 * finite, so CEM still ranks it and a buffer's summed loss stays a number. */
#define NDS_REPLAY_DIVERGED 1e6

/* One rollout's loss terms. */
typedef struct {
  double pos_o;   /* 1/T sum |y_o - y~_o|^2, m^2 */
  double pos_ee;  /* 1/T sum |y_ee - y~_ee|^2, m^2 */
  double rot_o;   /* 1/T sum of the angle between v(phi) and v(phi~), rad */
  int steps;      /* T: observations compared (the normaliser, also when cut) */
  int diverged;   /* non-finite state or a MuJoCo warning; terms are NDS_REPLAY_DIVERGED */
  int cut;        /* nds_replay_bounded stopped early: terms are the sums so far / T,
                     lower bounds of the full replay's */
} nds_replay_terms;

/* Columns of a predicted trajectory row: object x, y, yaw, sphere x, y. */
#define NDS_REPLAY_PRED_COLS 5

/* Model steps per record step for replaying r in nm: k >= 1 when the model's timestep is
 * k times r->dt (within 1e-9 relative), else -1 with a message. Also checks the shape of
 * r (n >= k, known control mode, arrays present), not its values. */
int nds_replay_ratio(const nds_model *nm, const nd_rollout *r, char *err, int errlen);

/* nds_replay_ratio plus every value: finite initial state with a non-zero quaternion,
 * finite controls and observations. Scans the whole record: call it once per record,
 * not per replay. Return 0, or -1 naming the first bad value. */
int nds_replay_check(const nds_model *nm, const nd_rollout *r, char *err, int errlen);

/* Replay r in nm (any theta) on d (scratch: any prior content, overwritten; its warning
 * counters are preset so MuJoCo does not print for divergences reported here). ctrl is
 * used in velocity mode only. pred, if not NULL, receives n / k rows of
 * NDS_REPLAY_PRED_COLS (rows after a divergence are NaN). Allocates nothing. Return 0
 * with out filled, or -1 with a message if nds_replay_ratio refuses r (out zeroed). A
 * record with bad values that nds_replay_check would refuse replays as diverged. */
int nds_replay(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl, const nd_rollout *r,
               nds_replay_terms *out, double *pred, char *err, int errlen);

/* nds_replay without a prediction that gives up as soon as the rollout's L (weights k1,
 * k2) must exceed bound: out->cut = 1 then. bound = INFINITY replays in full, exactly as
 * nds_replay does. For a search that needs only the candidates below some threshold. */
int nds_replay_bounded(const nds_model *nm, mjData *d, const nds_ctrl_cfg *ctrl,
                       const nd_rollout *r, double k1, double k2, double bound,
                       nds_replay_terms *out, char *err, int errlen);

/* L of one rollout's terms: pos_o + k1 pos_ee + k2 rot_o. */
double nds_replay_loss(const nds_replay_terms *t, double k1, double k2);

/* What a recorder and the replay must agree on, so a replay of the recording model is
 * exact: the observation read from d (object x, y, yaw; sphere x, y) ... */
void nds_replay_observe(const nds_model *nm, const mjData *d, double obj[3], double ee[2]);

/* ... and the initial state, copied between a record and an nds_state. */
void nds_replay_start_get(const nd_rollout *r, nds_state *s);
void nds_replay_start_put(nd_rollout *r, const nds_state *s);

#endif
