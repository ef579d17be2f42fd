/* nds_model: the pushing scene as a MuJoCo model, and applying theta to it.
 *
 * The scene is a table plane, a cuboid object on a free joint and a spherical
 * end-effector on two slide joints (x, y) held at table height. An nds_model owns one
 * mjModel plus the indices the rest of sim/ needs; it is constant once built, except
 * through nds_theta_apply. Workers that need different theta own their own copy. */
#ifndef NDS_MODEL_H
#define NDS_MODEL_H

#include <mujoco/mujoco.h>

#include "nd_theta.h"

/* The sphere's centre floats this far above the table: it never touches it (contact
 * excluded); the gap only keeps the two apart when drawn. */
#define NDS_EE_GAP 0.001

/* Solver and sizes of the generated scenes (doc/decisions.md#scene-solver): Newton with an
 * elliptic cone, capped iterations; a box on a plane makes at most 4 contacts and the
 * sphere 1 more, so small contact and stack sizes keep each mjData ~1.3 MB, not ~13 MB. */
#define NDS_ITERATIONS 20
#define NDS_TOLERANCE 1e-8
#define NDS_NCONMAX 32
#define NDS_NSTACK 100000

typedef struct {
  double obj_half[3];    /* cuboid half sizes (x, y, z), m */
  double obj_mass;       /* kg */
  double obj_com[3];     /* centre of mass in the box frame, m (the planning model's: 0) */
  double solref[2];      /* contact softness: time constant (s), damping ratio */
  double solimp[3];      /* contact impedance: d0, dwidth, width (m) */
  double ee_radius;      /* m */
  double timestep;       /* s */
  int condim;            /* 3, 4 or 6: torsional needs >= 4, rolling needs 6 */
  double tilt_damping;   /* N m s/rad on the object's roll and pitch dofs only (>= 0) */
  double theta[ND_NTHETA];
} nds_scene_cfg;

/* Defaults: 10 x 6 x 5 cm, 0.5 kg box with its centre of mass in the middle; MuJoCo's
 * default contact softness (solref 0.02 1, solimp 0.9 0.95 0.001); 2.5 cm sphere; 1 ms;
 * condim 6; tilt damping 0.1; nd_theta_true. The tilt damping keeps a sliding box from rocking on its soft corner
 * contacts at coarse timesteps (MuJoCo's Euler integrates it implicitly), which worsened
 * the planning model's prediction; it leaves yaw and translation free, and a box that
 * stays flat, as a pushed box does, never feels it (doc/decisions.md#tilt-damping). */
void nds_scene_cfg_default(nds_scene_cfg *cfg);

typedef struct {
  mjModel *m;
  nds_scene_cfg cfg;      /* what the model was built from (theta tracks nds_theta_apply) */
  int obj_body, ee_body;
  int obj_qpos, obj_dof;  /* free joint: qpos 7 (pos, w-first quat), dof 6 */
  int ee_qpos[2], ee_dof[2];
  double ee_height;       /* z of the sphere centre */
  /* The mass-dependent values theta scales, as loaded: nds_theta_apply sets them from
   * these, so applying a theta gives the same bits whatever was applied before. */
  double ee_mass0, ee_inertia0[3];
  double obj_mass0, obj_inertia0[3], obj_ipos0[3];
  /* MuJoCo's shortcuts for a box whose centre of mass is its frame's origin, as loaded;
   * a shifted centre of mass turns them off (nds_theta_apply). */
  mjtByte obj_sameframe0, obj_simple0;
  mjData *d0;             /* scratch for mj_setConst, owned */
} nds_model;

/* The planning model's scene at step dt: the defaults, except at 10 ms (the live
 * planner's step), where MuJoCo's contact stepped that coarsely pushes the box ~2.4 cm
 * too far over 0.6 s; there the contact softness and tilt damping nudge-calibrate fitted to the
 * 1 ms world replace the world's (doc/decisions.md#plan-contact). Return 1 if they did. */
int nds_scene_cfg_planning(nds_scene_cfg *cfg, double dt);

/* Check cfg: finite positive sizes and masses, timestep in (0, 0.05] s, condim 3, 4 or 6,
 * the sphere centre below the object top, theta valid. Return 0, or -1 naming the value. */
int nds_scene_cfg_check(const nds_scene_cfg *cfg, char *err, int errlen);

/* Write the scene's MJCF for cfg into buf. Return 0, or -1 with a message. */
int nds_scene_xml(const nds_scene_cfg *cfg, char *buf, int len, char *err, int errlen);

/* The pieces other scenes (the lab world's) share with it, each appended at buf[*at]:
 * the head (<mujoco> to <worldbody> with the table: solver, sizes, cfg's condim, theta's
 * frictions and contact softness for every geom) and the object's body. Return 0, or -1 if
 * buf (len bytes) is full. */
int nds_scene_xml_head(const nds_scene_cfg *cfg, const char *name, char *buf, int len,
                       int *at);
int nds_scene_xml_object(const nds_scene_cfg *cfg, char *buf, int len, int *at);

/* Build the model of cfg (validated, theta applied; tilt_damping is set on the model after
 * loading, since MJCF damps all six dofs of a free joint alike). Return 0, or -1 with a
 * message. */
int nds_model_init(nds_model *nm, const nds_scene_cfg *cfg, char *err, int errlen);

/* Load a user MJCF file that has bodies "object" (free joint) and "ee" (slide joints
 * "ee_x", "ee_y"); theta from cfg is applied, everything else is the file's (nm->cfg
 * records the file's timestep, box size, sphere radius, condim). Return 0, or -1 naming
 * the file and what is missing. */
int nds_model_load_file(nds_model *nm, const char *path, const nds_scene_cfg *cfg,
                        char *err, int errlen);

/* Deep copy src into dst (own mjModel). Return 0, or -1 with a message. */
int nds_model_copy(nds_model *dst, const nds_model *src, char *err, int errlen);

/* Free what nm owns; nm may be zeroed or half-built. */
void nds_model_free(nds_model *nm);

/* Apply theta to the model's contacts and sphere mass. Return 0, or -1 (model unchanged). */
int nds_theta_apply(nds_model *nm, const double theta[ND_NTHETA], char *err, int errlen);

/* Count d's active contacts (as the last mj_step or mj_forward left them) between the
 * object and the world's geoms (the table), and between the object and the sphere. */
void nds_contacts(const nds_model *nm, const mjData *d, int *obj_table, int *obj_ee);

#endif
