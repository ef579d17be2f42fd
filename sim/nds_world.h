/* nds_world: the emulated world behind the robot and motion-capture channels: a MuJoCo
 * scene with its own true theta, the robot following setpoints at its control rate, and
 * what its sensors report. The bridge steps it in real time; a real deployment replaces
 * it with hardware.
 *
 * The ideal world is the planning model's own scene: a sphere on two slide joints driven
 * by the tracking controller (nds_ctrl), exact sensing, motion capture without noise or
 * delay. Stepping never allocates, locks or does I/O (the bridge's 1 kHz loop calls it). */
#ifndef NDS_WORLD_H
#define NDS_WORLD_H

#include "nd_mocap.h"
#include "nds_ctrl.h"
#include "nds_model.h"
#include "nds_state.h"

enum { NDS_WORLD_IDEAL = 0 };

typedef struct {
  int kind;                 /* NDS_WORLD_* */
  double dt;                /* step = the robot's control period, s; 0: the --model file's */
  double theta[ND_NTHETA];  /* the world's true parameters */
  double obj[3];            /* start: object pose x, y, yaw (m, m, rad) */
  double ee[2];             /* start: sphere x, y (m) */
  const char *model_path;   /* ideal world: an MJCF file instead of the built-in scene */
  nd_mocap_cfg mocap;       /* the motion capture: rate, noise, latency, drops */
} nds_world_cfg;

/* The ideal world at 1 ms with the true theta, the object at the origin, the sphere at
 * (-0.10, 0), exact motion capture at 240 Hz (the paper's rate). */
void nds_world_cfg_default(nds_world_cfg *cfg);

/* What the robot reports after a step (its ROBOT_STATE). */
typedef struct {
  double ee_pos[3], ee_vel[3];
  double ee_force[3];       /* the force the robot applied to the sphere during the step */
} nds_world_robot;

/* One motion-capture frame. */
typedef struct {
  double capture_t;         /* world time of the capture, s */
  double obj_pos[3], obj_quat[4];
  double ee_pos[3];
} nds_world_frame;

#define NDS_WORLD_MAX_FRAMES 4

typedef struct {
  nds_world_robot robot;
  int nframes;              /* frames released by this step */
  nds_world_frame frame[NDS_WORLD_MAX_FRAMES];
  int reset;                /* the world diverged and was reset to its start this step */
} nds_world_out;

typedef struct nds_world nds_world;

/* Build the world of cfg; the sphere must start clear of the object. NULL and a message
 * naming the bad value on error. */
nds_world *nds_world_create(const nds_world_cfg *cfg, char *err, int errlen);
void nds_world_free(nds_world *w);

/* The scene (sizes, timestep) and the configuration it was built from. */
const nds_model *nds_world_model(const nds_world *w);
const nds_world_cfg *nds_world_config(const nds_world *w);

/* Where the sphere is now (x, y): a robot holding still holds here. */
void nds_world_ee(const nds_world *w, double ee[2]);

/* Step the world once with the robot tracking setpoint sp[axis][p, v, a, j]; out says what
 * the sensors report. A diverged world (non-finite state, MuJoCo's instability warnings)
 * is reset to its start. Allocation-free. */
void nds_world_step(nds_world *w, const double sp[2][4], nds_world_out *out);

/* World time, s. */
double nds_world_time(const nds_world *w);

#endif
