/* nds_panda: an emulated Franka Emika Panda arm with a sphere tool, for the lab world.
 *
 * The arm is MJCF generated here from Franka's modified DH table, its published limits and
 * the link inertias Gaz et al. identified; MuJoCo bodies are the DH frames, so the plain-C
 * kinematics below and MuJoCo's agree to rounding. A rod on the flange carries the
 * project's end-effector sphere (site "tool" at its centre), held pointing straight down
 * at the pushing height. The arm is driven by torque: motor actuators of gear 1, one per
 * joint, ctrl = tau in N m. Only the sphere collides, with everything but the world body's
 * geoms (the table): the scene must keep nds_panda_xml_contact's <exclude>.
 *
 * Control (1 kHz, allocation-free): a Cartesian impedance law on the sphere with the tool
 * held down and a null-space pull to the rest posture (nds_panda_ctrl_impedance); a
 * joint-space hold for a stopped arm (nds_panda_ctrl_brake); and libfranka-like reflexes
 * on the measured joints and the commanded setpoint (nds_panda_monitor_check). Joints are
 * indexed 0..6 here and named 1..7 in messages, as Franka numbers them. */
#ifndef NDS_PANDA_H
#define NDS_PANDA_H

#include <mujoco/mujoco.h>

#include "nds_model.h"

#define NDS_PANDA_NJ 7

/* Franka's published limits for the Panda ("Limits for Panda", frankaemika.github.io/docs/
 * control_parameters.html): joint position (rad), velocity (rad/s), acceleration (rad/s^2),
 * jerk (rad/s^3) and torque (N m) per joint; Cartesian translation below. */
extern const double nds_panda_q_min[NDS_PANDA_NJ], nds_panda_q_max[NDS_PANDA_NJ];
extern const double nds_panda_dq_max[NDS_PANDA_NJ], nds_panda_ddq_max[NDS_PANDA_NJ];
extern const double nds_panda_dddq_max[NDS_PANDA_NJ], nds_panda_tau_max[NDS_PANDA_NJ];
#define NDS_PANDA_CART_V_MAX 1.7    /* m/s */
#define NDS_PANDA_CART_A_MAX 13.0   /* m/s^2 */
#define NDS_PANDA_CART_J_MAX 6500.0 /* m/s^3 */

/* Franka's modified (Craig) DH table, joints 1..7: frame i = frame i-1 * RotX(alpha[i]) *
 * TransX(a[i]) * TransZ(d[i]) * RotZ(q[i]); the flange is frame 7 moved NDS_PANDA_FLANGE_D
 * along its z. Same source as the limits. */
extern const double nds_panda_dh_a[NDS_PANDA_NJ], nds_panda_dh_d[NDS_PANDA_NJ];
extern const double nds_panda_dh_alpha[NDS_PANDA_NJ];
#define NDS_PANDA_FLANGE_D 0.107

/* The pushing region the default arm serves (world, m; the table top is z = 0): on a 5 cm
 * grid every point has an IK solution NDS_PANDA_IK_MARGIN inside every joint limit, from
 * which the sphere can move at 0.5 m/s in any horizontal direction with every joint below
 * 90% of its velocity limit, and accelerate from rest at 2 m/s^2 within the joint
 * acceleration limits (joint 2's 7.5 rad/s^2 binds there: 2 m/s^2 is the arm's figure, not
 * a margin). Smaller than the ideal world's box: no upright Panda beside the table
 * serves a 0.7 x 0.8 m region at 0.5 m/s (doc/lab-world.md#reach). */
#define NDS_PANDA_WS_XMIN (-0.15)
#define NDS_PANDA_WS_XMAX 0.15
#define NDS_PANDA_WS_YMIN (-0.30)
#define NDS_PANDA_WS_YMAX 0.40
#define NDS_PANDA_WS_SPEED 0.5       /* m/s */
#define NDS_PANDA_WS_SPEED_RATIO 0.9 /* of the joint velocity limits */
#define NDS_PANDA_WS_ACCEL 2.0       /* m/s^2 */

typedef struct {
  double base_pos[3];  /* base frame (DH frame 0: joint 1's axis at the mounting face), m */
  double base_yaw;     /* base rotation about world z, rad */
  double tool_length;  /* flange to sphere centre along the flange's z, m */
  double ee_radius;    /* sphere radius, m */
  double tool_mass;    /* rod + sphere, kg */
  double q_rest[NDS_PANDA_NJ]; /* rest posture: IK seed and null-space target, rad */
} nds_panda_cfg;

/* The lab world's arm: base at (-0.30, 0.05, -0.30) facing +x (on a stand beside the
 * table, its mounting face 0.30 m below the top), 0.20 m tool, 2.5 cm sphere, 0.25 kg tool,
 * rest posture with the sphere at the start (-0.10, 0). */
void nds_panda_cfg_default(nds_panda_cfg *cfg);

/* Check cfg: finite, positive sizes and mass, rest posture inside the joint limits. Return
 * 0, or -1 naming the value. */
int nds_panda_cfg_check(const nds_panda_cfg *cfg, char *err, int errlen);

/* Height of the sphere centre when pushing: ee_radius + NDS_EE_GAP (nds_model.h), as in
 * the planning scene. */
double nds_panda_push_height(const nds_panda_cfg *cfg);

/* ---- MJCF ---- */

/* Write the arm subtree (<body name="panda_link0"> ... </body>, for <worldbody>) into buf.
 * Bodies panda_link0..7 and panda_tool, joints panda_joint1..7, sites panda_flange and
 * tool, geom panda_sphere. No <default> is needed: every attribute is explicit. Return 0,
 * or -1 with a message. */
int nds_panda_xml_body(const nds_panda_cfg *cfg, char *buf, int len, char *err, int errlen);

/* Write the <exclude> of the sphere against the world body's geoms (for <contact>) and the
 * seven <motor> actuators panda_motor1..7 (for <actuator>). Return 0, or -1. */
int nds_panda_xml_contact(char *buf, int len, char *err, int errlen);
int nds_panda_xml_actuator(char *buf, int len, char *err, int errlen);

/* Write a complete scene: scene's head (nds_scene_xml_head: solver, 1 ms or scene's step,
 * theta's frictions and contact softness; NULL: nds_scene_cfg_default), the arm, and if
 * with_box scene's object (body and geom "object"). Return 0, or -1. */
int nds_panda_scene_xml(const nds_panda_cfg *cfg, const nds_scene_cfg *scene, int with_box,
                        char *buf, int len, char *err, int errlen);

/* Load nds_panda_scene_xml's scene. Return the model, or NULL with a message. */
mjModel *nds_panda_scene_load(const nds_panda_cfg *cfg, const nds_scene_cfg *scene,
                              int with_box, char *err, int errlen);

/* ---- the arm in a model ---- */

typedef struct {
  nds_panda_cfg cfg;
  int qpos[NDS_PANDA_NJ], dof[NDS_PANDA_NJ], act[NDS_PANDA_NJ];
  int body[NDS_PANDA_NJ + 1]; /* panda_link0..7 */
  int body_tool, geom_sphere, site_tool, site_flange;
} nds_panda;

/* Find the arm's joints, actuators, bodies and sites in m (a scene holding
 * nds_panda_xml_body of cfg and its contact and actuator pieces) and check their structure
 * and that the arm is cfg's (its sites where nds_panda_fk puts them). Return 0, or -1
 * naming what is missing or wrong. */
int nds_panda_resolve(nds_panda *p, const mjModel *m, const nds_panda_cfg *cfg, char *err,
                      int errlen);

/* Put the arm at q, at rest, with zero ctrl (other dofs untouched), then mj_forward. */
void nds_panda_set_q(const nds_panda *p, const mjModel *m, mjData *d,
                     const double q[NDS_PANDA_NJ]);

/* Read the arm's joint positions and velocities (either may be NULL). */
void nds_panda_get_q(const nds_panda *p, const mjData *d, double q[NDS_PANDA_NJ],
                     double dq[NDS_PANDA_NJ]);

/* Write tau into the arm's actuators' ctrl. */
void nds_panda_apply(const nds_panda *p, mjData *d, const double tau[NDS_PANDA_NJ]);

/* ---- kinematics in plain C (no MuJoCo) ---- */

/* Flange pose (pos, row-major rotation R, both world) and sphere centre of q; any output
 * may be NULL. */
void nds_panda_fk(const nds_panda_cfg *cfg, const double q[NDS_PANDA_NJ], double pos[3],
                  double R[9], double tool[3]);

/* The sphere task's Jacobian at q: rows 0-2 the sphere centre's world velocity, rows 3-4
 * the world x and y angular velocity (the tool axis' tilt when it points down), 5 x 7
 * row-major. */
void nds_panda_jac(const nds_panda_cfg *cfg, const double q[NDS_PANDA_NJ], double J[35]);

/* The sphere task's error toward target with the tool pointing down, from the sphere centre
 * tool and the flange rotation fR: position (3, world) and tilt (2, world x and y rotation
 * that would turn the tool axis straight down). */
void nds_panda_task_error(const double tool[3], const double fR[9], const double target[3],
                          double e[5]);

/* IK stays this far (rad) inside every joint limit; a target that needs less fails. */
#define NDS_PANDA_IK_MARGIN 0.15

/* Joints q with the sphere centre at target (world) and the tool pointing straight down,
 * by damped least squares from seed (NULL: cfg->q_rest) with a null-space pull toward
 * cfg->q_rest, to 1e-9 m and 1e-9 rad. Return 0, or -1 saying why (unreachable, or a joint
 * within NDS_PANDA_IK_MARGIN of a limit); q is then the last iterate. */
int nds_panda_ik(const nds_panda_cfg *cfg, const double target[3],
                 const double seed[NDS_PANDA_NJ], double q[NDS_PANDA_NJ], char *err,
                 int errlen);

/* The minimum-norm joint rates per unit sphere rate, tool held down, at q: rates[i][0]
 * of joint i along world x, rates[i][1] along y. Return 0, or -1 at a singularity. */
int nds_panda_rate_map(const nds_panda_cfg *cfg, const double q[NDS_PANDA_NJ],
                       double rates[NDS_PANDA_NJ][2]);

/* How close moving the sphere at speed v (m/s) in any horizontal direction, tool held
 * down, brings the joints at q to their velocity limits: max_i |dq_i| / dq_max_i of the
 * minimum-norm joint velocity. Infinite at a singularity. */
double nds_panda_speed_ratio(const nds_panda_cfg *cfg, const double q[NDS_PANDA_NJ],
                             double v);

/* The same for a sphere acceleration a (m/s^2) from rest against the joint acceleration
 * limits (at speed, the velocity-product terms add to it). */
double nds_panda_accel_ratio(const nds_panda_cfg *cfg, const double q[NDS_PANDA_NJ],
                             double a);

/* ---- control ---- */

typedef struct {
  double k_t, d_t;   /* sphere position stiffness (N/m) and damping (N s/m) */
  double k_r, d_r;   /* tool tilt stiffness (N m/rad) and damping (N m s/rad) */
  double k_ns, d_ns; /* null-space posture stiffness (N m/rad) and damping (N m s/rad) */
  int accel_ff;      /* 1: feed the desired acceleration forward through the task inertia */
} nds_panda_gains;

/* k_t 2000, d_t 2 sqrt(k_t * 8 kg), k_r 150, d_r 2 sqrt(k_r * 0.1 kg m^2), k_ns 10, d_ns 1,
 * accel_ff 1 (the reasons are at the definition). */
void nds_panda_gains_default(nds_panda_gains *g);

/* The controller's working memory, sized for one model and allocated once. */
typedef struct {
  nds_panda_gains g;
  int nv;
  mjtNum *jacp, *jacr; /* 3 x nv each */
  mjtNum *rows, *minv; /* task rows and M^-1 times them, 5 x nv each */
} nds_panda_ctrl;

/* Allocate c for m. Return 0, or -1 (out of memory, bad gains). */
int nds_panda_ctrl_init(nds_panda_ctrl *c, const mjModel *m, const nds_panda_gains *g,
                        char *err, int errlen);

/* Free what c owns; c may be zeroed or half-built. */
void nds_panda_ctrl_free(nds_panda_ctrl *c);

/* Impedance torques toward the sphere setpoint p_des, v_des, a_des (world, finite; a_des
 * may be NULL) with the tool held down, from d's position and velocity stages (mj_step1
 * or mj_forward just ran): tau = J' (K e + D de + Lambda (a_des - dJ dq)) + N (k_ns
 * (q_rest - q) - d_ns dq) + qfrc_bias, N the null-space projector of J, each clamped to
 * the torque limit. J is the 5-row task Jacobian (sphere position, tool tilt). Return a
 * mask of the joints clamped (bit i for joint i; 0: none), or -1 if c was sized for a
 * model with another nv (tau then compensates gravity only). No allocation, locks or I/O;
 * ~2 us. */
int nds_panda_ctrl_impedance(nds_panda_ctrl *c, const nds_panda *p, const mjModel *m,
                             mjData *d, const double p_des[3], const double v_des[3],
                             const double a_des[3], double tau[NDS_PANDA_NJ]);

/* Joint PD gains of the brake law: libfranka's joint impedance example. */
extern const double nds_panda_brake_kp[NDS_PANDA_NJ], nds_panda_brake_kd[NDS_PANDA_NJ];

/* Torques that hold the arm at q_hold (a stopped robot braking): joint PD plus d's
 * qfrc_bias (gravity and Coriolis; position and velocity stages current), clamped to the
 * torque limits. Return the mask of joints clamped. Allocation-free. */
int nds_panda_ctrl_brake(const nds_panda *p, const mjData *d,
                         const double q_hold[NDS_PANDA_NJ], double tau[NDS_PANDA_NJ]);

/* ---- reflexes ---- */

/* Numbered as robot_state_t's REFLEX_* codes, so a bridge can publish them as they are; 4
 * (REFLEX_JOINT_TORQUE) is not produced: the control laws clamp torques instead and say so
 * in their return masks. NONFINITE has no code there. */
typedef enum {
  NDS_PANDA_REFLEX_NONE = 0,
  NDS_PANDA_REFLEX_JOINT_POSITION = 1,     /* measured */
  NDS_PANDA_REFLEX_JOINT_VELOCITY = 2,     /* measured */
  NDS_PANDA_REFLEX_JOINT_ACCELERATION = 3, /* measured velocity, differenced */
  NDS_PANDA_REFLEX_CART_VELOCITY = 5,      /* commanded position, differenced */
  NDS_PANDA_REFLEX_CART_ACCELERATION = 6,
  NDS_PANDA_REFLEX_CART_JERK = 7,
  NDS_PANDA_REFLEX_NONFINITE = 8 /* a measured or commanded value is not finite */
} nds_panda_reflex_kind;

typedef struct {
  nds_panda_reflex_kind kind;
  int joint;    /* 0..6 for the joint kinds (robot_state_t counts 1..7), -1 otherwise */
  double value; /* what broke the limit (signed for joints, a norm for Cartesian) */
  double limit; /* the limit it broke (the bound on the side it crossed) */
} nds_panda_reflex;

/* Most cycles a measured joint acceleration can be differenced over. */
#define NDS_PANDA_ACCEL_WINDOW_MAX 64

/* What the reflex check remembers between cycles. */
typedef struct {
  double dt;
  int accel_window; /* cycles; 0: no acceleration check */
  double dq_hist[NDS_PANDA_ACCEL_WINDOW_MAX + 1][NDS_PANDA_NJ]; /* velocities, a ring */
  int head, n_dq;       /* next slot to write; earlier velocities held (0..window) */
  double p_hist[4][3];  /* the last four commanded positions, newest first */
  int n_p;              /* valid rows of p_hist (0..4) */
} nds_panda_monitor;

/* Forget the history. dt is the control period (s); accel_window the cycles over which a
 * measured joint velocity is differenced into an acceleration (1: consecutive cycles;
 * 0: no acceleration check; clamped to NDS_PANDA_ACCEL_WINDOW_MAX). */
void nds_panda_monitor_reset(nds_panda_monitor *mo, double dt, int accel_window);

/* The window for an arm that pushes. The sphere striking the 0.5 kg box reads as joint 6
 * accelerating at 4.6 times its limit over 1 ms, 1.8 over 10 ms, 0.94 over 20 ms and 0.41
 * over 50 ms (doc/lab-world.md#reflexes): an impact is a contact force, not a motion the arm was commanded,
 * and a sustained excess still shows within 50 ms. */
#define NDS_PANDA_ACCEL_WINDOW_PUSH 50

/* A new motion starts from where the robot holds: forget the commanded positions, so the
 * Cartesian checks difference only the new motion's commands. */
void nds_panda_monitor_new_motion(nds_panda_monitor *mo);

/* One control cycle's check, in this order: measured joint positions against the limits
 * less libfranka's kLimitEps, velocities against libfranka's kMaxJointVelocity,
 * accelerations (velocity differenced over the window) against kMaxJointAcceleration,
 * then the commanded sphere position p_cmd's velocity, acceleration and jerk (its 1st, 2nd
 * and 3rd differences over the last cycles) against kMaxTranslational*. The first break in
 * that order goes into r (r->kind NONE if none). Return 1 if a limit broke, else 0.
 * Allocation-free. */
int nds_panda_monitor_check(nds_panda_monitor *mo, const double q[NDS_PANDA_NJ],
                            const double dq[NDS_PANDA_NJ], const double p_cmd[3],
                            nds_panda_reflex *r);

/* What r names, e.g. "joint 4 velocity" or "Cartesian acceleration", into buf; returns
 * buf. */
const char *nds_panda_reflex_name(const nds_panda_reflex *r, char *buf, int len);

#endif
