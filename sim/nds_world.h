/* nds_world: the emulated world behind the robot and motion-capture channels: a MuJoCo
 * scene with its own true parameters, the robot following setpoints at its control rate,
 * and what its sensors report. The bridge steps it in real time; a real deployment
 * replaces it with hardware.
 *
 * Two presets (doc/lab-world.md):
 *  - ideal: the planning model's own scene, a sphere on two slide joints driven by the
 *    tracking controller (nds_ctrl), exact sensing, motion capture without noise or delay;
 *  - lab: what a real set-up differs in. The sphere is the tool of a 7-DoF Panda under
 *    Cartesian impedance control in joint torques, with libfranka's reflexes (a broken
 *    limit brakes the arm until nds_world_resume); the robot state comes from forward
 *    kinematics of noisy joint readings and its force from joint torques; the motion
 *    capture is noisy, late and drops frames (nd_mocap); the object and its contact differ
 *    from the planning model beyond theta (size, mass, centre of mass, contact softness,
 *    no tilt damping).
 * Each part of the lab has its own setting, so one can be switched off. Stepping never
 * allocates, locks or does I/O (the bridge's 1 kHz loop calls it). */
#ifndef NDS_WORLD_H
#define NDS_WORLD_H

#include <stdint.h>

#include "nd_mocap.h"
#include "nds_model.h"
#include "nds_panda.h"

enum { NDS_WORLD_IDEAL = 0, NDS_WORLD_LAB = 1 };

typedef struct {
  int kind;                 /* NDS_WORLD_*: what the preset was (the parts below decide) */
  double dt;                /* step = the robot's control period, s; 0: the --model file's */
  double theta[ND_NTHETA];  /* true frictions (and, without the arm, the sphere's mass) */
  double obj[3];            /* start: object pose x, y, yaw (m, m, rad) */
  double ee[2];             /* start: sphere x, y (m) */
  const char *model_path;   /* an MJCF file instead of the built-in scene (no arm) */
  nd_mocap_cfg mocap;       /* the motion capture: rate, noise, latency, drops */
  nds_scene_cfg object;     /* the object as it really is: sizes, mass, centre of mass,
                               contact softness, tilt damping (theta and dt from above) */
  int arm;                  /* 1: the Panda holds the sphere; 0: the sphere on slide joints */
  nds_panda_cfg panda;      /* the arm (base pose, tool, rest posture) */
  double encoder_noise;     /* rad: std of the arm's joint position readings */
  double velocity_noise;    /* rad/s: std of its joint velocity readings */
  double torque_noise;      /* N m: std of its joint torque readings (the force estimate) */
  uint64_t seed;            /* the robot's sensor noise */
} nds_world_cfg;

/* The ideal world at 1 ms with the true theta, the object at the origin, the sphere at
 * (-0.10, 0), exact motion capture at 240 Hz (the paper's rate). */
void nds_world_cfg_default(nds_world_cfg *cfg);

/* The lab world: the ideal world's start with the Panda, nd_mocap_cfg_lab's motion capture,
 * encoder noise 1e-5 rad, velocity noise 1e-3 rad/s, torque noise 0.05 N m, and the lab's
 * object: 10.2 x 6.1 x 5 cm, 0.55 kg, centre of mass 8 mm off along x and 4 mm along y and
 * down, a stiffer contact (solref 0.01 1, solimp 0.95 0.99 0.001), no tilt damping. The
 * reasons for each number are in doc/lab-world.md. */
void nds_world_cfg_lab(nds_world_cfg *cfg);

/* What the robot reports after a step (its ROBOT_STATE). */
typedef struct {
  double ee_pos[3], ee_vel[3];
  double ee_force[3];       /* the force the robot applies at the sphere: exact (ideal), or
                               estimated from joint torques (the arm) */
  int stopped;              /* a reflex stopped the arm: it brakes until resumed */
  nds_panda_reflex reflex;  /* which limit broke (kind NONE while not stopped) */
  int arm;                  /* the fields below hold the arm's joints */
  double q[NDS_PANDA_NJ], dq[NDS_PANDA_NJ], tau[NDS_PANDA_NJ];
} nds_world_robot;

/* One motion-capture frame. */
typedef struct {
  int64_t index;            /* the camera's frame number: dropped frames leave gaps */
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
  int stopped_now;          /* a reflex stopped the arm this step */
} nds_world_out;

typedef struct nds_world nds_world;

/* Build the world of cfg; the sphere must start clear of the object (and, with the arm,
 * where the arm reaches). NULL and a message naming the bad value on error. */
nds_world *nds_world_create(const nds_world_cfg *cfg, char *err, int errlen);
void nds_world_free(nds_world *w);

/* The configuration it was built from (dt the model's). */
const nds_world_cfg *nds_world_config(const nds_world *w);

/* The object's size and the sphere's radius, as the world has them. */
void nds_world_sizes(const nds_world *w, double obj_half[3], double *ee_radius);

/* Where the sphere is now (x, y): a robot holding still holds here. */
void nds_world_ee(const nds_world *w, double ee[2]);

/* Step the world once with the robot tracking setpoint sp[axis][p, v, a, j]; out says what
 * the sensors report. A diverged world (non-finite state, MuJoCo's instability warnings)
 * is reset to its start. Allocation-free. */
void nds_world_step(nds_world *w, const double sp[2][4], nds_world_out *out);

/* Release a stopped arm (the next task or PLACE): it tracks setpoints again, from where it
 * stopped. */
void nds_world_resume(nds_world *w);

/* A new motion begins (commands after a hold, or a hold after commands): the reflexes
 * forget the commanded path before it, as a robot does when a new motion starts from where
 * it holds (the hold is the true position, a commander's start a noisy reading of it: 10 um
 * is 10^4 m/s^3 of jerk in one step). */
void nds_world_motion_start(nds_world *w);

/* Put the object at rest at (x, y, yaw) on the table, as an operator resets it between
 * tasks, if the sphere's surface is at least clear (m) from its sides there. Returns that
 * gap (m): the object is placed when it is >= clear, else left as it is. Allocation-free. */
double nds_world_place(nds_world *w, double x, double y, double yaw, double clear);

/* World time, s. */
double nds_world_time(const nds_world *w);

/* The MuJoCo model and data, for drawing and tests (not for stepping). */
const mjModel *nds_world_mj_model(const nds_world *w);
const mjData *nds_world_mj_data(const nds_world *w);

#endif
