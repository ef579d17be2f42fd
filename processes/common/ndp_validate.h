/* ndp_validate: the one place that decides whether an incoming message is usable.
 * Every process runs every decoded input through these before using it; a refused
 * message is counted in status and never reaches the algorithms. Each returns 0, or
 * -1 with a reason naming the offending field. */
#ifndef NDP_VALIDATE_H
#define NDP_VALIDATE_H

#include "nudge/nudge_arm_state_t.h"
#include "nudge/nudge_ee_cmd_t.h"
#include "nudge/nudge_episode_t.h"
#include "nudge/nudge_mocap_t.h"
#include "nudge/nudge_params_t.h"
#include "nudge/nudge_place_t.h"
#include "nudge/nudge_plan_t.h"
#include "nudge/nudge_robot_state_t.h"
#include "nudge/nudge_status_t.h"
#include "nudge/nudge_task_t.h"
#include "nd_snap.h"

#include "nd_theta.h"

_Static_assert(ND_MAX_KEYS == NUDGE_PLAN_T_MAX_KEYPOINTS,
               "plan_t carries as many keypoints as the planner and executor handle");
_Static_assert(sizeof(((nudge_params_t *)0)->theta_mean) == ND_NTHETA * sizeof(double) &&
                   sizeof(((nudge_params_t *)0)->theta_std) == ND_NTHETA * sizeof(double),
               "params_t carries all of theta");

/* Bounds shared by the checks: the workspace is a few metres at most, nothing a pushing
 * robot does exceeds these by orders of magnitude. */
#define NDP_MAX_POS 10.0     /* m */
#define NDP_MAX_VEL 20.0     /* m/s */
#define NDP_MAX_ACC 1000.0   /* m/s^2 */
#define NDP_MAX_JERK 1e6     /* m/s^3 */
#define NDP_MAX_FORCE 1e5    /* N */

int ndp_check_mocap(const nudge_mocap_t *m, char *why, int len);
int ndp_check_robot_state(const nudge_robot_state_t *m, char *why, int len);
int ndp_check_ee_cmd(const nudge_ee_cmd_t *m, char *why, int len);
int ndp_check_plan(const nudge_plan_t *m, char *why, int len);
int ndp_check_task(const nudge_task_t *m, char *why, int len);
int ndp_check_params(const nudge_params_t *m, char *why, int len);
int ndp_check_arm_state(const nudge_arm_state_t *m, char *why, int len);
int ndp_check_episode(const nudge_episode_t *m, char *why, int len);
/* clear within [0, NDP_MAX_PLACE_CLEAR] m. */
int ndp_check_place(const nudge_place_t *m, char *why, int len);
#define NDP_MAX_PLACE_CLEAR 0.1

/* Decode EPISODE / STATUS bytes (the types with strings) without trusting them: the
 * decoders lcm-gen 1.3.1 generates take a string's length word as given, so a negative
 * one makes them memcpy to NULL (the process dies), zero leaves the string without its
 * NUL, and one beyond the message leaks what they allocated. These check every string
 * field against the buffer first. Return 0 with *m decoded (free with
 * nudge_X_t_decode_cleanup), or -1 with a reason and nothing to free. Subscribe with
 * lcm_subscribe and call these instead of nudge_X_t_subscribe. */
int ndp_decode_episode(const void *buf, int len, nudge_episode_t *m, char *why, int wlen);

/* ndp_decode_episode, then ndp_check_episode: 0 with *m decoded and valid (free with
 * nudge_episode_t_decode_cleanup), or -1 with a reason and nothing to free. */
int ndp_take_episode(const void *buf, int len, nudge_episode_t *m, char *why, int wlen);
int ndp_decode_status(const void *buf, int len, nudge_status_t *m, char *why, int wlen);

#endif
