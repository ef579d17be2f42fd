/* bridge_opts: nudge-bridge's command line (bridge_io.h). */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "bridge_io.h"
#include "nd_exec.h"
#include "ndp_validate.h"

static int parse_mode(const char *v, const char *what, void *dst, char *err, int errlen) {
  (void)dst;
  if (!strcmp(v, "emulation")) return 0;
  snprintf(err, errlen,
           "%s %s is not available: this build has only the emulation mode. A real hardware "
           "bridge publishes the same channels (%s, %s) from the motion capture and the robot, "
           "and follows %s the same way (doc/robot.md)",
           what, v, NDP_CH_MOCAP, NDP_CH_ROBOT_STATE, NDP_CH_EE_CMD);
  return -1;
}

static const char *const world_words[] = {"ideal", "lab", NULL};
static const char *const onoff[] = {"off", "on", NULL};

/* The lab world's parts, each an option of its own: as given, else the preset's. */
typedef struct {
  int arm;
  double mocap_noise[2], mocap_latency[2], mocap_drops[2];
  uint64_t mocap_seed;
  double robot_noise[3];
  double size[3], mass, com[3], solref[2], solimp[3], tilt;
} lab_parts;

static void parts_of(const nds_world_cfg *c, lab_parts *p) {
  const nd_mocap_cfg *m = &c->mocap;
  const nds_scene_cfg *o = &c->object;
  p->arm = c->arm;
  p->mocap_noise[0] = m->sigma_pos, p->mocap_noise[1] = m->sigma_rot;
  p->mocap_latency[0] = m->latency, p->mocap_latency[1] = m->latency_jitter;
  p->mocap_drops[0] = m->drop_prob * m->drop_burst, p->mocap_drops[1] = m->drop_burst;
  p->mocap_seed = m->seed;
  p->robot_noise[0] = c->encoder_noise, p->robot_noise[1] = c->velocity_noise;
  p->robot_noise[2] = c->torque_noise;
  for (int k = 0; k < 3; k++) p->size[k] = 2 * o->obj_half[k], p->com[k] = o->obj_com[k];
  p->mass = o->obj_mass;
  memcpy(p->solref, o->solref, sizeof(p->solref));
  memcpy(p->solimp, o->solimp, sizeof(p->solimp));
  p->tilt = o->tilt_damping;
}

/* Write parts p into c, each only where given[i] (or all with given NULL). */
static void apply_parts(const lab_parts *p, const int *given, nds_world_cfg *c) {
  nd_mocap_cfg *m = &c->mocap;
  nds_scene_cfg *o = &c->object;
#define GIVEN(i) (!given || given[i])
  if (GIVEN(0)) c->arm = p->arm;
  if (GIVEN(1)) m->sigma_pos = p->mocap_noise[0], m->sigma_rot = p->mocap_noise[1];
  if (GIVEN(2)) m->latency = p->mocap_latency[0], m->latency_jitter = p->mocap_latency[1];
  if (GIVEN(3)) m->drop_burst = p->mocap_drops[1], m->drop_prob = p->mocap_drops[0] / p->mocap_drops[1];
  if (GIVEN(4)) m->seed = p->mocap_seed;
  if (GIVEN(5)) {
    c->encoder_noise = p->robot_noise[0], c->velocity_noise = p->robot_noise[1];
    c->torque_noise = p->robot_noise[2];
  }
  for (int k = 0; k < 3; k++) {
    if (GIVEN(6)) o->obj_half[k] = 0.5 * p->size[k];
    if (GIVEN(8)) o->obj_com[k] = p->com[k];
  }
  if (GIVEN(7)) o->obj_mass = p->mass;
  if (GIVEN(9)) memcpy(o->solref, p->solref, sizeof(o->solref));
  if (GIVEN(10)) memcpy(o->solimp, p->solimp, sizeof(o->solimp));
  if (GIVEN(11)) o->tilt_damping = p->tilt;
#undef GIVEN
}

int bridge_options(int argc, char **argv, bridge_opts *o) {
  nds_world_cfg_default(&o->wc);
  int world = NDS_WORLD_IDEAL;
  lab_parts lp, ideal, lab;
  nds_world_cfg lab_cfg;
  nds_world_cfg_lab(&lab_cfg);
  parts_of(&o->wc, &ideal);
  parts_of(&lab_cfg, &lab);
  lp = ideal;
  char defs[12][120];
  snprintf(defs[0], 120, "ideal: off; lab: on");
  snprintf(defs[1], 120, "ideal: 0,0; lab: %g,%g", lab.mocap_noise[0], lab.mocap_noise[1]);
  snprintf(defs[2], 120, "ideal: 0,0; lab: %g,%g", lab.mocap_latency[0], lab.mocap_latency[1]);
  snprintf(defs[3], 120, "ideal: 0,1; lab: %g,%g", lab.mocap_drops[0], lab.mocap_drops[1]);
  snprintf(defs[5], 120, "ideal: 0,0,0; lab: %g,%g,%g", lab.robot_noise[0], lab.robot_noise[1],
           lab.robot_noise[2]);
  snprintf(defs[6], 120, "ideal: %g,%g,%g; lab: %g,%g,%g", ideal.size[0], ideal.size[1],
           ideal.size[2], lab.size[0], lab.size[1], lab.size[2]);
  snprintf(defs[7], 120, "ideal: %g; lab: %g", ideal.mass, lab.mass);
  snprintf(defs[8], 120, "ideal: 0,0,0; lab: %g,%g,%g", lab.com[0], lab.com[1], lab.com[2]);
  snprintf(defs[9], 120, "ideal: %g,%g; lab: %g,%g", ideal.solref[0], ideal.solref[1],
           lab.solref[0], lab.solref[1]);
  snprintf(defs[10], 120, "ideal: %g,%g,%g; lab: %g,%g,%g", ideal.solimp[0], ideal.solimp[1],
           ideal.solimp[2], lab.solimp[0], lab.solimp[1], lab.solimp[2]);
  snprintf(defs[11], 120, "ideal: %g; lab: %g", ideal.tilt, lab.tilt);
  nd_rtloop_cfg_default(&o->rt);
  o->rt.policy = ND_RT_CATCH_UP;
  o->ws = (nd_box){{ND_EXEC_WS_LO, ND_EXEC_WS_LO}, {ND_EXEC_WS_HI, ND_EXEC_WS_HI}};
  o->cmd_timeout = 0.1;
  int no_rt = 0;
  nd_opt opts[] = {
      {"mode", ND_OPT_CUSTOM, NULL, .parse = parse_mode, .arg = "MODE", .def = "emulation",
       .help = "emulation, the only mode of this build"},
      {"rate", ND_OPT_DOUBLE, &o->rt.rate, 20.0, 10000.0, .arg = "HZ", .def = "1000, or the "
       "--model file's own timestep",
       .help = "world steps per second of real time; timestep 1/HZ"},
      {"mocap-hz", ND_OPT_DOUBLE, &o->wc.mocap.rate, 1.0, 10000.0, .arg = "HZ", .help = "MOCAP rate"},
      {"cmd-timeout", ND_OPT_DOUBLE, &o->cmd_timeout, 1e-3, 60.0, .arg = "S",
       .help = "hold when the newest EE_CMD is older than S"},
      {"theta", ND_OPT_THETA, o->wc.theta,
       .help = "the world's sliding, torsional, rolling friction and sphere mass [kg]"},
      {"object", ND_OPT_LIST, o->wc.obj, -NDP_MAX_POS, NDP_MAX_POS, 3, .arg = "X,Y,YAW",
       .help = "initial object pose, m, m, rad"},
      {"ee", ND_OPT_LIST, o->wc.ee, -NDP_MAX_POS, NDP_MAX_POS, 2, .arg = "X,Y",
       .help = "initial sphere position, m, inside the workspace"},
      {"workspace", ND_OPT_BOX, &o->ws,
       .help = "box in metres: an EE_CMD whose position lies beyond it by more than 0.05 m "
               "is refused and counted; the robot goes on with the last valid command, then "
               "holds (nudge-planner's keypoint box; nudge-up --workspace gives the planner, "
               "executor and bridge one box)"},
      {"model", ND_OPT_STRING, &o->wc.model_path, .arg = "FILE", .def = "the built-in scene",
       .help = "MJCF with bodies \"object\" (free joint) and \"ee\" (slide joints \"ee_x\", "
               "\"ee_y\")"},
      {"seconds", ND_OPT_DOUBLE, &o->seconds, 1e-3, 1e9, .arg = "S", .def = "until SIGINT/SIGTERM",
       .help = "run S seconds, then exit 0"},
      {"lcm-url", ND_OPT_STRING, &o->url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
      {"no-rt", ND_OPT_FLAG, &no_rt, .help = "do not ask for SCHED_FIFO and mlockall"},
      {"world", ND_OPT_CHOICE, &world, .choices = world_words, .arg = "NAME",
       .help = "ideal: the planning model's own scene with exact sensing; lab: a Panda arm, "
               "motion capture with noise, latency and drops, robot sensing with noise, and "
               "an object and contact unlike the model's (doc/lab-world.md). Each part below "
               "has its own option; given ones override the preset"},
      {"arm", ND_OPT_CHOICE, &lp.arm, .choices = onoff, .def = defs[0],
       .help = "the Panda holds the sphere (impedance control, reflexes) or the sphere moves "
               "on slide joints under the tracking controller"},
      {"mocap-noise", ND_OPT_LIST, lp.mocap_noise, 0, 0.1, 2, .arg = "POS,ROT", .def = defs[1],
       .help = "motion capture noise: position std (m) and orientation std (rad) per axis"},
      {"mocap-latency", ND_OPT_LIST, lp.mocap_latency, 0, 1, 2, .arg = "S,JITTER", .def = defs[2],
       .help = "capture to publication, s, and its uniform jitter (<= the latency); MOCAP's "
               "utime stays the capture time"},
      {"mocap-drops", ND_OPT_LIST, lp.mocap_drops, 0, 1000, 2, .arg = "SHARE,BURST", .def = defs[3],
       .help = "share of frames lost (< 0.9) and the mean length of a loss, frames (>= 1)"},
      {"mocap-seed", ND_OPT_U64, &lp.mocap_seed, .help = "seed of the motion capture's noise"},
      {"robot-noise", ND_OPT_LIST, lp.robot_noise, 0, 100, 3, .arg = "ENC,VEL,TORQUE", .def = defs[5],
       .help = "the arm's joint readings: position (rad), velocity (rad/s) and torque (N m) "
               "noise stds"},
      {"object-size", ND_OPT_LIST, lp.size, 0.01, 1, 3, .arg = "L,W,H", .def = defs[6],
       .help = "the world's box, m (the planner's model is 0.1,0.06,0.05)"},
      {"object-mass", ND_OPT_DOUBLE, &lp.mass, 0.01, 100, .arg = "KG", .def = defs[7],
       .help = "the world's box mass"},
      {"object-com", ND_OPT_LIST, lp.com, -0.5, 0.5, 3, .arg = "X,Y,Z", .def = defs[8],
       .help = "its centre of mass in the box frame, m"},
      {"solref", ND_OPT_LIST, lp.solref, 1e-4, 1, 2, .arg = "T,DAMP", .def = defs[9],
       .help = "the world's contact softness: time constant (s) and damping ratio"},
      {"solimp", ND_OPT_LIST, lp.solimp, 1e-4, 1, 3, .arg = "D0,D1,W", .def = defs[10],
       .help = "the world's contact impedance"},
      {"tilt-damping", ND_OPT_DOUBLE, &lp.tilt, 0, 100, .arg = "NMS", .def = defs[11],
       .help = "damping of the box's roll and pitch, N m s/rad (a planning-model device)"},
  };
  nd_opt_spec spec = {"nudge-bridge", "[options]",
                      "Mocap/robot bridge. Emulation mode: a MuJoCo pushing scene with the "
                      "true theta, stepped in real time; the robot's tracking controller "
                      "follows EE_CMD and holds when commands go stale. Publishes ROBOT_STATE "
                      "every step and MOCAP (object pose, end-effector position) at the mocap "
                      "rate; heartbeat on STATUS.",
                      "Exit status: 0 after SIGINT/SIGTERM or --seconds, 1 on a runtime failure "
                      "(LCM), 2 on bad\narguments, a --model file among them (missing, "
                      "malformed, unusable).\n", opts, sizeof(opts) / sizeof(opts[0])};
  o->spec = spec;
  int st = nd_opt_parse(&o->spec, argc, argv);
  if (st != ND_OPT_RUN) return st;
  /* The preset, then the parts given. */
  static const char *const part[12] = {"arm", "mocap-noise", "mocap-latency", "mocap-drops",
                                       "mocap-seed", "robot-noise", "object-size",
                                       "object-mass", "object-com", "solref", "solimp",
                                       "tilt-damping"};
  int given[12];
  for (int i = 0; i < 12; i++) given[i] = nd_opt_find(&o->spec, part[i])->given;
  o->wc.kind = world;
  if (world == NDS_WORLD_LAB) apply_parts(&lab, NULL, &o->wc);
  if (given[3] && !(lp.mocap_drops[0] < 0.9 && lp.mocap_drops[1] >= 1))
    return nd_opt_fail(&o->spec, "--mocap-drops %g,%g: need a share below 0.9 and bursts of at "
                       "least 1 frame", lp.mocap_drops[0], lp.mocap_drops[1]);
  apply_parts(&lp, given, &o->wc);
  if (o->wc.arm && o->wc.model_path)
    return nd_opt_fail(&o->spec, "--model has no arm: give --arm off with it");
  /* Simulated time is real time: a --model file's timestep sets the rate unless --rate does. */
  const nds_world_cfg *wc = &o->wc;
  const nd_box *ws = &o->ws;
  o->wc.dt = wc->model_path && !nd_opt_find(&o->spec, "rate")->given ? 0 : 1.0 / o->rt.rate;
  if (no_rt) o->rt.priority = o->rt.io_priority = o->rt.lock_memory = 0;
  if (wc->ee[0] < ws->lo[0] || wc->ee[0] > ws->hi[0] || wc->ee[1] < ws->lo[1] ||
      wc->ee[1] > ws->hi[1])
    return nd_opt_fail(&o->spec, "the sphere at --ee %g,%g starts outside the workspace x "
                       "[%g, %g], y [%g, %g] m (--workspace)", wc->ee[0], wc->ee[1], ws->lo[0],
                       ws->hi[0], ws->lo[1], ws->hi[1]);
  o->spec.opts = NULL;  /* the table lives on this stack; refusals need only the name */
  o->spec.n = 0;
  return ND_OPT_RUN;
}

