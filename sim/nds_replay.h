/* nds_replay: replaying a recorded rollout in the model, and how far the model strays.
 *
 * The replay starts the model in the rollout's initial state and drives the sphere in one
 * of three modes (nds_replay_cfg.mode):
 *   FORCE     u of a force record is the force on the sphere's two dofs, open loop (the
 *             paper's simulation replay);
 *   VELOCITY  the sphere tracks u of a velocity record with nds_ctrl_vel (the paper's
 *             robot replay);
 *   SETPOINT  the recorded setpoints sp go through the robot's tracking controller
 *             nds_ctrl_pid, integral reset at the start: closed loop, as the recording
 *             ran. Any record (both kinds carry sp).
 * After each step the model's object (x, y, yaw of its pose) and sphere (x, y) are
 * compared with what was observed, giving one rollout's terms of the adaptation loss
 * (doc/design.md#refit):
 *
 *   L = L_pos,o + k1 L_pos,ee + k2 L_rot,o, each term 1/T sum over the T compared steps.
 *
 * The fit replays FORCE, re-anchored (below; nds_fit_cfg_default). Open loop, the sphere
 * drifts from the recorded path as soon as contact differs under a candidate theta, which
 * makes a one-shot force replay rough in theta; re-anchoring bounds that drift to a window.
 * SETPOINT keeps the sphere on its path through the PID, as the real controller did, but
 * thereby hides sliding friction: the box follows the sphere whatever the table's friction
 * (doc/decisions.md#replay-mode). Under the recording theta FORCE and SETPOINT are exact:
 * the PID recomputes the recorded force bit for bit.
 *
 * A model whose timestep is k times the record's (k a whole number) replays k recorded
 * steps per model step and compares every k-th observation: FORCE and VELOCITY with the
 * mean of the k controls, SETPOINT with the setpoint of the block's first step and the
 * controller run at the model's step (a slower controller sampling the same setpoints). */
#ifndef NDS_REPLAY_H
#define NDS_REPLAY_H

#include "nd_rollout.h"
#include "nds_ctrl.h"
#include "nds_state.h"

/* What a diverged replay scores in each term (m^2 for the positions, rad for yaw): far
 * above anything a replay that stays finite on a table can reach (a 1 km mean error), yet
 * finite, so CEM still ranks it and a buffer's summed loss stays a number. */
#define NDS_REPLAY_DIVERGED 1e6

/* How the sphere is driven (see above). */
enum { NDS_REPLAY_FORCE = 0, NDS_REPLAY_VELOCITY = 1, NDS_REPLAY_SETPOINT = 2 };

typedef struct {
  int mode;            /* NDS_REPLAY_* */
  nds_ctrl_cfg ctrl;   /* the robot's controller: VELOCITY uses kv (0, the default: the
                          sphere reaches the recorded velocity in one model step), SETPOINT
                          the PID */
  double window;       /* s; > 0: re-anchor every window (below); 0: one shot from the
                          initial state, the paper's replay */
  double smooth;       /* s; > 0: re-anchor the object on a local fit of its observations
                          within smooth of the anchor (below); 0: on the observation */
  double phase;        /* s, in [0, window): the anchors fall window - phase, 2 window -
                          phase, ... into the record; 0, the default: window, 2 window, ...
                          (the robust score's windows stay unshifted) */
  double skip_clear;   /* m; > 0 in VELOCITY with window > 0: windows clear of contact are
                          predicted, not simulated (below); 0, the default: none */
} nds_replay_cfg;

/* Clear windows. In VELOCITY the sphere follows its record whatever theta (its gains
 * scale with its mass), so a window in which the recorded sphere stays skip_clear or more
 * from the model's box at the anchor, and the recorded object stays within
 * NDS_REPLAY_STILL_POS and NDS_REPLAY_STILL_ROT of its anchor pose, tells nothing about
 * theta. Its steps are scored as the object resting at the anchor and the sphere on its
 * record, without stepping the model. Which windows are clear depends on the record
 * alone, so every candidate theta skips the same ones. */
#define NDS_REPLAY_STILL_POS 1e-3  /* m: a box pushed or coasting moves more in a window */
#define NDS_REPLAY_STILL_ROT 0.02  /* rad: ten times motion capture's noise on the lab */

/* Re-anchoring (multiple shooting). With window > 0, every window seconds of model time
 * the replay puts what was observed back into the model: the object's full pose (position
 * and orientation, as motion capture sees it) and its rates, the sphere's x, y and
 * velocity (rates as backward differences of the observations one record step apart,
 * which is the velocity an Euler step leaves); only the controller's integral and the
 * solver's warm start stay the model's own. Each window then scores how far the model
 * strays in window seconds from a state that really happened, so an error does not
 * compound over the rollout: a contact that starts or ends a little earlier under a
 * candidate theta costs only within its window. The height and tilt matter: MuJoCo's soft
 * contact lifts a sliding box by up to a millimetre, and when each corner lands again
 * depends chaotically on theta, so a replay that kept its own height and tilt started
 * each window from a different hop and its loss was white noise within ~2 % of the truth
 * (doc/decisions.md#box-lift). At the recording theta the replay stays exact up to
 * rounding.
 * With smooth > 0 the object's anchor is a straight-line least-squares fit, in time, of
 * its observations within smooth seconds (positions, and the orientations as rotation
 * vectors from the anchored one): the fit's value is the pose, its slope the rates. Of the
 * fits over +-smooth, the smooth before and the smooth after, the one whose x and y lie
 * closest to it is taken, so a push's start or stop is not smeared across the anchor.
 * Motion capture frames carry noise (the lab's 2e-3 rad a frame is ~0.7 rad/s as a
 * difference over one frame); a fit over n frames divides it by about n^1.5. Exact
 * records need none: it would only blur them (doc/decisions.md#anchor-fit). */

/* mode with the default controller (nds_ctrl_cfg_default), no re-anchoring. */
void nds_replay_cfg_default(nds_replay_cfg *cfg, int mode);

/* Check cfg's mode, window, smooth and phase. Return 0, or -1 naming the bad field. */
int nds_replay_cfg_check(const nds_replay_cfg *cfg, char *err, int errlen);

/* "force", "velocity", "setpoint"; "?" for an unknown mode. */
const char *nds_replay_mode_name(int mode);

/* One rollout's loss terms. */
typedef struct {
  double pos_o;   /* 1/T sum |y_o - y~_o|^2, m^2 */
  double pos_ee;  /* 1/T sum |y_ee - y~_ee|^2, m^2 */
  double rot_o;   /* 1/T sum of the angle between v(phi) and v(phi~), rad */
  int steps;      /* T: observations compared (the normaliser, also when cut) */
  int diverged;   /* non-finite state or a MuJoCo warning; terms are NDS_REPLAY_DIVERGED */
  int cut;        /* nds_replay_bounded stopped early: terms are the sums so far / T,
                     lower bounds of the full replay's */
  int skipped;    /* of the steps compared, those of clear windows (cfg.skip_clear) */
  double robust;  /* nds_replay_bounded with robust > 0: the windows' score (below);
                     else 0 */
} nds_replay_terms;

/* Columns of a predicted trajectory row: object x, y, yaw, sphere x, y. */
#define NDS_REPLAY_PRED_COLS 5

/* Model steps per record step for replaying r in nm: k >= 1 when the model's timestep is
 * k times r->dt (within 1e-9 relative), else -1 with a message. Also checks the shape of
 * r (n >= k, known control mode, all four step arrays present), not its values. */
int nds_replay_ratio(const nds_model *nm, const nd_rollout *r, char *err, int errlen);

/* nds_replay_ratio plus every value: finite initial state with a non-zero quaternion,
 * finite controls, setpoints and observations. Scans the whole record: call it once per record,
 * not per replay. Return 0, or -1 naming the first bad value. */
int nds_replay_check(const nds_model *nm, const nd_rollout *r, char *err, int errlen);

/* Replay r in nm (any theta) on d (scratch: any prior content, overwritten; its warning
 * counters are preset so MuJoCo does not print for divergences reported here) as cfg says.
 * pred, if not NULL, receives n / k rows of NDS_REPLAY_PRED_COLS (rows after a divergence
 * are NaN). Allocates nothing. Return 0 with out filled, or -1 with a message if
 * nds_replay_ratio refuses r, the mode is unknown, or FORCE / VELOCITY meets a record of
 * the other control kind (out zeroed). A record with bad values that nds_replay_check
 * would refuse replays as diverged. */
int nds_replay(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg, const nd_rollout *r,
               nds_replay_terms *out, double *pred, char *err, int errlen);

/* nds_replay without a prediction that gives up as soon as the rollout's L (weights k1,
 * k2) must exceed bound: out->cut = 1 then. bound = INFINITY replays in full, exactly as
 * nds_replay does. For a search that needs only the candidates below some threshold.
 * With robust > 0 (m^2) it also scores the rollout robustly, and bound applies to that:
 *
 *   out->robust = 1/N sum_w log(1 + e_w / robust),
 *   e_w = 1/|w| sum_{t in w} |y_o - y~_o|^2 + k1 |y_ee - y~_ee|^2 + k2 |phi - phi~|
 *
 * over the N re-anchoring windows w (the whole replay is one when cfg->window is 0): each
 * window's L, through the Cauchy loss of scale robust. Why: where contacts make a few
 * windows' errors jump by orders of magnitude for a tiny change of theta, L, a sum of
 * squares, is mostly those few windows; the log lets every window count. An option: the
 * fit ranks by L (doc/decisions.md#robust-score). */
int nds_replay_bounded(const nds_model *nm, mjData *d, const nds_replay_cfg *cfg,
                       const nd_rollout *r, double k1, double k2, double robust,
                       double bound, nds_replay_terms *out, char *err, int errlen);

/* L of one rollout's terms: pos_o + k1 pos_ee + k2 rot_o. */
double nds_replay_loss(const nds_replay_terms *t, double k1, double k2);

/* What a recorder and the replay must agree on, so a replay of the recording model is
 * exact: the observation read from d (object pose: x, y, z, quaternion w, x, y, z; sphere
 * x, y) ... */
void nds_replay_observe(const nds_model *nm, const mjData *d, double obj[ND_ROLLOUT_OBJ],
                        double ee[2]);

/* ... the initial state, copied between a record and an nds_state ... */
void nds_replay_start_get(const nd_rollout *r, nds_state *s);
void nds_replay_start_put(nd_rollout *r, const nds_state *s);

/* ... and the setpoint of a step: row[6] = (px, py, vx, vy, ax, ay) of sp[axis][p, v, a, j]
 * (the PID does not use jerk; get sets it to 0). */
void nds_replay_sp_put(double row[6], const double sp[2][4]);
void nds_replay_sp_get(const double row[6], double sp[2][4]);

#endif
