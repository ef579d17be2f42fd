/* bridge_opts: nudge-bridge's command line (bridge_io.h). */
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

int bridge_options(int argc, char **argv, bridge_opts *o) {
  nds_world_cfg_default(&o->wc);
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

