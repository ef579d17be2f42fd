/* nds_reach: how near the arm's joint limits a sphere motion takes it, mapped over the
 * table, so a planner can rank motions the arm cannot make behind those it can.
 *
 * On a grid over a box, each cell holds the inverse kinematics' joints (tool down, seeded
 * from the neighbour solved before) and from them the joint rates per unit sphere rate
 * along x and y (nds_panda_rate_map), so a motion's load follows its direction: moving
 * radially folds the elbow several times faster than moving across; their slopes give the
 * joints' velocity-product accelerations at speed (up to 0.56 of a limit at 0.5 m/s in the
 * lab box). A cell whose IK fails or comes within NDS_PANDA_IK_MARGIN of a joint limit is
 * unreachable. Built once (allocates); the queries allocate nothing. */
#ifndef NDS_REACH_H
#define NDS_REACH_H

#include "nds_panda.h"

typedef struct {
  double lo[2], step;   /* grid origin (cell 0's centre) and spacing, m */
  int nx, ny;
  float *rate;          /* per cell, row-major in y: NDS_PANDA_NJ x 2 joint rates per unit
                           sphere rate along x, y; inf: no IK */
  float *slope;         /* per cell: each rate's slope along x and y, 1/m (rate-major) */
  int unreachable;      /* cells without an IK solution */
} nds_reach;

/* Map the box lo..hi (m, table frame) at spacing step for the arm cfg. Return 0, or -1 with
 * a message (bad box, out of memory). */
int nds_reach_build(nds_reach *r, const nds_panda_cfg *cfg, const double lo[2],
                    const double hi[2], double step, char *err, int errlen);
void nds_reach_free(nds_reach *r);

/* The planner's map for the default arm: the keypoints' box ws_lo..ws_hi plus the room
 * segments and brakes take beyond it (ND_EXEC_WS_MARGIN and 1 cm), at 2 cm. As
 * nds_reach_build. */
int nds_reach_build_ws(nds_reach *r, const double ws_lo[2], const double ws_hi[2], char *err,
                       int errlen);

/* The joints' rates qd and accelerations qdd moving the sphere at p with velocity v and
 * acceleration a (x, y), from the interpolated rates and their slopes (the
 * velocity-product terms included). Return 0, or -1 at an unreachable cell or outside the
 * box. */
int nds_reach_joint(const nds_reach *r, const double p[2], const double v[2],
                    const double a[2], double qd[NDS_PANDA_NJ], double qdd[NDS_PANDA_NJ]);

/* The arm's load moving the sphere so: the largest joint velocity or acceleration over its
 * limit (1 = at a limit; nds_reach_joint); infinite where that fails. */
double nds_reach_load(const nds_reach *r, const double p[2], const double v[2],
                      const double a[2]);

#endif
