/* nds_state: the world state the planner syncs to, read from and written into mjData. */
#ifndef NDS_STATE_H
#define NDS_STATE_H

#include "nds_model.h"

typedef struct {
  double obj_pos[3];   /* object position, world */
  double obj_quat[4];  /* object orientation, w-first */
  double obj_vel[6];   /* free-joint velocity as MuJoCo stores it (linear world, angular local) */
  double ee_pos[2];    /* sphere centre (x, y) */
  double ee_vel[2];
} nds_state;

/* Read the state of d. */
void nds_state_get(const nds_model *nm, const mjData *d, nds_state *s);

/* Put s into d without copying a whole mjData: qpos, qvel, time = 0, and every input or
 * warm start that would make a rollout depend on d's history reset. The quaternion is
 * normalised. Return 0, or -1 if s is not finite or the quaternion is zero. */
int nds_state_set(const nds_model *nm, mjData *d, const nds_state *s, char *err, int errlen);

/* A resting state: object at (x, y, yaw) on the table, sphere at ee (x, y), all still. */
void nds_state_rest(const nds_model *nm, double x, double y, double yaw, const double ee[2],
                    nds_state *s);

/* Object yaw of s. */
double nds_state_yaw(const nds_state *s);

#endif
