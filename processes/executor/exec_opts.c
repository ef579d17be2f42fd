/* exec_opts: nudge-executor's command line (exec_io.h). */
#include <stdio.h>

#include "exec_io.h"
#include "nd_opt.h"

int exec_options(int argc, char **argv, exec_opts *o) {
  o->cfg = nd_exec_cfg_default();
  nd_box ws = {{o->cfg.ws_lo[0], o->cfg.ws_lo[1]}, {o->cfg.ws_hi[0], o->cfg.ws_hi[1]}};
  nd_rtloop_cfg_default(&o->rt);
  o->timeout = 0.1;
  /* Plans come at the planner's rate (the paper's robot: 10 Hz), each a segment of 0.3 s
   * or more: following one for 0.3 s rides over a late plan or two without braking
   * (doc/decisions.md#plan-timeout). */
  o->plan_timeout = 0.3;
  int no_rt = 0;
  char ws_help[300];
  snprintf(ws_help, sizeof ws_help,
           "box in metres every keypoint of a PLAN must lie in; a plan with one outside, or "
           "whose segment or brake to rest would leave the box by more than %g m, is refused "
           "and counted (nudge-planner's keypoint box; nudge-up --workspace gives the planner, "
           "executor and bridge one box)", o->cfg.ws_margin);
  nd_opt opts[] = {
      {"rate", ND_OPT_DOUBLE, &o->rt.rate, 1.0, 10000.0, .arg = "HZ", .help = "loop rate"},
      {"timeout", ND_OPT_DOUBLE, &o->timeout, 1e-3, 60.0, .arg = "S",
       .help = "ROBOT_STATE older than this is stale; age counts from the message's utime, "
               "so hosts need synced clocks"},
      {"plan-timeout", ND_OPT_DOUBLE, &o->plan_timeout, 1e-3, 60.0, .arg = "S",
       .help = "a PLAN older than this is stale: the robot brakes to rest and holds until a "
               "fresh one (age from the plan's utime)"},
      {"v-max", ND_OPT_DOUBLE, &o->cfg.v_max, 1e-3, 10.0, .arg = "M/S", .help = "speed limit"},
      {"a-max", ND_OPT_DOUBLE, &o->cfg.a_max, 1e-3, 1000.0, .arg = "M/S2",
       .help = "acceleration limit"},
      {"j-max", ND_OPT_DOUBLE, &o->cfg.j_max, 1e-3, 1e6, .arg = "M/S3", .help = "jerk limit"},
      {"brake-a-max", ND_OPT_DOUBLE, &o->cfg.brake_a_max, 0.0, 1000.0, .arg = "M/S2",
       .help = "acceleration limit of the brake to rest when PLAN or ROBOT_STATE goes stale, "
               "where an arm's joints take less than --a-max (0: --a-max)"},
      {"workspace", ND_OPT_BOX, &ws, .help = ws_help},
      {"lcm-url", ND_OPT_STRING, &o->url, .arg = "URL",
       .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL, .help = "LCM URL"},
      {"no-rt", ND_OPT_FLAG, &no_rt, .help = "do not ask for SCHED_FIFO and mlockall"},
  };
  nd_opt_spec spec = {"nudge-executor", "[options]",
                      "Follow the newest PLAN's first keypoint with a minimum-snap segment and "
                      "publish the end-effector setpoint (p, v, a) on EE_CMD at a fixed rate. "
                      "Publishes nothing until the first ROBOT_STATE; brakes to rest and holds "
                      "while PLAN or ROBOT_STATE is stale; a fresh plan resumes.",
                      "Subscribes PLAN, ROBOT_STATE; publishes EE_CMD, STATUS (1 Hz).\n", opts,
                      sizeof(opts) / sizeof(opts[0])};
  const int st = nd_opt_parse(&spec, argc, argv);
  if (st != ND_OPT_RUN) return st;
  for (int k = 0; k < 2; k++) o->cfg.ws_lo[k] = ws.lo[k], o->cfg.ws_hi[k] = ws.hi[k];
  char err[300];
  if (nd_exec_cfg_check(&o->cfg, err, sizeof err)) return nd_opt_fail(&spec, "%s", err);
  if (no_rt) o->rt.priority = o->rt.io_priority = o->rt.lock_memory = 0;
  return ND_OPT_RUN;
}
