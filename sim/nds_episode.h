/* nds_episode: one pushing task in the paper's simulation protocol.
 *
 * A world model (1 ms, the "real" theta) is stepped with the robot's tracking controller
 * following the executor's setpoints. Every plan_period of simulated time the world is
 * paused, the planner plans from its exact state, and the executor switches to the plan's
 * first keypoint. Deterministic for a given planner seed. Used by nudge-demo, the tests
 * and the experiment driver. */
#ifndef NDS_EPISODE_H
#define NDS_EPISODE_H

#include "nd_exec.h"
#include "nds_planner.h"

typedef struct {
  double eps;          /* success threshold on L_pos + w_rot L_rot (paper: 1e-2) */
  double eps_fine;     /* a second, tighter threshold also reported (1e-3); the episode
                        * runs on until it is met or tau passes */
  double tau;          /* time limit, s (paper: 5) */
  double plan_period;  /* simulated time between plans, s (paper: 0.05) */
  nd_exec_cfg exec;    /* the executor's limits */
} nds_episode_cfg;

void nds_episode_cfg_default(nds_episode_cfg *cfg);

/* Called after every world step (for recording) with the setpoint the controller tracked
 * during the step, sp[axis][p, v, a, j], and the force it applied. The controller used
 * p, v and a of sp: nds_ctrl_pid on them reproduces force (see nds_replay.h, SETPOINT). */
typedef void (*nds_episode_hook)(void *ctx, const nds_model *world, const mjData *d,
                                 const double sp[2][4], const double force[2]);

typedef struct {
  int reached;         /* task error fell below eps within tau */
  double t_reached;    /* when, s (tau if not reached) */
  int reached_fine;    /* below eps_fine within tau */
  double t_fine;
  double t_end;        /* simulated time when the episode stopped */
  double pos_err;      /* final |object - goal|, m */
  double yaw_err;      /* final yaw error modulo pi, rad, in [0, pi/2] */
  double task_error;   /* final L_pos + w_rot L_rot */
  int plans;           /* planning steps */
  double plan_ms;      /* mean wall time of a planning step, ms */
} nds_episode_out;

/* Run one task from start toward goal on world model `world` with data d (overwritten).
 * hook may be NULL. Return 0, or -1 with a message (bad start state, planner failure). */
int nds_episode_run(const nds_model *world, mjData *d, nds_planner *planner,
                    const nds_ctrl_cfg *ctrl, const nds_episode_cfg *cfg,
                    const nds_state *start, const nd_goal *goal, nds_episode_hook hook,
                    void *hook_ctx, nds_episode_out *out, char *err, int errlen);

#endif
