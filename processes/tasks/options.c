/* options: nudge-tasks' command line and its default goal chain (tasks.h). */
#include <stdio.h>
#include <string.h>

#include "nd_opt.h"
#include "tasks.h"

/* Start: object at rest at the origin, the bridge's sphere at (-0.10, 0). Each goal is a
 * 14-16 cm push from the previous one, so every task starts with the object near the last
 * goal and a push of about one object length ahead: straight ahead, a diagonal push with a
 * quarter turn, a push sideways onto the long face, a pull back that needs the sphere to go
 * around the object, and a diagonal push back with a turn the other way. All stay well
 * inside the default 0.5 m workspace, so the sphere has room behind the object. */
static const nd_goal chain[] = {
    {.x = 0.15, .y = 0.00, .yaw = 0.0}, {.x = 0.25, .y = 0.10, .yaw = 0.4},
    {.x = 0.25, .y = 0.25, .yaw = 0.8}, {.x = 0.10, .y = 0.30, .yaw = 0.8},
    {.x = 0.00, .y = 0.20, .yaw = 0.3},
};

/* The lab arm serves x [-0.15, 0.15], y [-0.30, 0.40] (sim/nds_panda.h): pushes of 15-18 cm,
 * laid out so the sphere's place behind the object (8 cm back along the push, 3 cm to the
 * side its turn needs) stays in that box at the start and end of each, the push from the
 * last goal back to the first included, so the chain can run twice: a diagonal push with a
 * turn, a push ahead with more turn, a pull back that needs the sphere to go around, back
 * across, and a diagonal push out toward the box's edge (decisions#lab-chain-rule). */
static const nd_goal chain_lab[] = {
    {.x = 0.09, .y = 0.12, .yaw = 0.4}, {.x = 0.06, .y = 0.30, .yaw = 0.8},
    {.x = -0.09, .y = 0.21, .yaw = 0.3}, {.x = 0.00, .y = 0.06, .yaw = 0.0},
    {.x = 0.12, .y = -0.06, .yaw = 0.3},
};
static const char *const world_words[] = {"ideal", "lab", NULL};
static const char *const control_words[] = {"force", "velocity", NULL};
static const char *const join_words[] = {"line", "cubic", NULL};
_Static_assert(ND_REC_JOIN_LINE == 0 && ND_REC_JOIN_CUBIC == 1, "join_words follow ND_REC_JOIN_*");
_Static_assert(ND_CTRL_FORCE == 0 && ND_CTRL_VELOCITY == 1, "control_words follow ND_CTRL_*");

static int add_goal(const char *v, const char *what, void *dst, char *err, int errlen) {
  tasks_cfg *c = dst;
  char why[400];
  if (c->n >= MAX_GOALS) {
    snprintf(err, errlen, "%s: more than %d goals", what, MAX_GOALS);
    return -1;
  }
  if (nd_goal_parse_arg(v, &c->goals[c->n], why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  c->n++;
  return 0;
}

static int set_place(const char *v, const char *what, void *dst, char *err, int errlen) {
  tasks_cfg *c = dst;
  char why[400];
  /* A goal's text without its optional EPS and TIME_LIMIT: exactly two commas. */
  const char *c1 = strchr(v, ','), *c2 = c1 ? strchr(c1 + 1, ',') : NULL;
  if (!c2 || strchr(c2 + 1, ',')) {
    snprintf(err, errlen, "%s: expected X,Y,YAW, got '%s'", what, v);
    return -1;
  }
  if (nd_goal_parse_arg(v, &c->place_pose, why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  c->place = 1;
  return 0;
}

static int add_goals(const char *v, const char *what, void *dst, char *err, int errlen) {
  tasks_cfg *c = dst;
  const int n0 = c->n;
  char why[400];
  if (nd_goal_list_load(v, c->goals, MAX_GOALS, &c->n, why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  if (c->n == n0) {
    snprintf(err, errlen, "%s: %s: no goals in the file", what, v);
    return -1;
  }
  return 0;
}

int tasks_options(int argc, char **argv, tasks_cfg *c) {
  *c = (tasks_cfg){.eps = 1e-2, .tau = 5.0, .workspace = 0.5, .wait = 10.0, .settle = 0.5,
                    .place_wait = 15.0,
                    .record_dt = 0.001, .record_join = ND_REC_JOIN_CUBIC};
  memcpy(c->theta, nd_theta_true, sizeof(c->theta));
  int world = 0;
  nd_opt opts[] = {
      {"goal", ND_OPT_CUSTOM, c, .parse = add_goal, .arg = "X,Y,YAW[,EPS[,TIME_LIMIT]]",
       .def = "", .help = "a goal pose (m, m, rad); repeatable, run in order"},
      {"goals", ND_OPT_CUSTOM, c, .parse = add_goals, .arg = "FILE", .def = "",
       .help = "goals from FILE, one per line: x y yaw [eps [time_limit]] ('#' comments, blank "
               "lines ignored); repeatable. Without goals: a chain of 5 pushes of 14-16 cm from "
               "the origin (laid out for the arm's reach with --world lab)"},
      {"world", ND_OPT_CHOICE, &world, .choices = world_words, .arg = "NAME",
       .help = "the bridge's world, for the defaults: with lab the goal chain fits the arm's "
               "reach and --tau is 8 s (the arm moves at 0.5 m/s, not 1.7)"},
      {"eps", ND_OPT_DOUBLE, &c->eps, 1e-12, 1.0, .arg = "E",
       .help = "success threshold on L_pos + 0.02 L_rot (per-goal values override)"},
      {"tau", ND_OPT_DOUBLE, &c->tau, 1e-3, ND_GOAL_MAX_TAU, .arg = "S",
       .help = "time limit per task, s (per-goal values override)"},
      {"v-max", ND_OPT_DOUBLE, &c->v_max, 0.0, NDP_MAX_VEL, .arg = "M/S", .def = "0: the planner's",
       .help = "end-effector speed limit the planner keeps to in these tasks (sent on TASK); a "
               "limit above the planner's own leaves it as it is. nudge-study's training pushes "
               "use it: a slow push shows the friction better"},
      {"workspace", ND_OPT_DOUBLE, &c->workspace, 1e-3, ND_GOAL_MAX_POS, .arg = "M",
       .help = "goals beyond |x| or |y| > M are rejected"},
      {"wait", ND_OPT_DOUBLE, &c->wait, 0.0, 3600.0, .arg = "S",
       .help = "wait for the first MOCAP frame (with --record: and ROBOT_STATE)"},
      {"settle", ND_OPT_DOUBLE, &c->settle, 0.0, 3600.0, .arg = "S",
       .help = "pause before each task, then until the object is at rest (under 1 cm/s) and "
               "the commands have held the sphere for 0.3 s (at most 5 s; a task they did not "
               "reach rest for is not recorded)"},
      {"record", ND_OPT_STRING, &c->record, .arg = "FILE",
       .help = "append each task's rollout (start state, 1 kHz forces, setpoints, observed "
               "path) to the replay buffer FILE, created if missing, for nudge-adapter; one "
               "writer at a time; a task whose object moved under 1 cm is not recorded"},
      {"record-dt", ND_OPT_DOUBLE, &c->record_dt, 1e-5, 0.05, .arg = "S",
       .help = "the robot's control step, s (the bridge's 1/--rate); a task whose ROBOT_STATE "
               "period differs is not recorded"},
      {"record-control", ND_OPT_CHOICE, &c->record_control, .choices = control_words,
       .arg = "KIND", .def = "force",
       .help = "what --record keeps as each step's control: the robot's force (ROBOT_STATE "
               "ee_force, for nudge-adapter --replay-mode force) or its end-effector velocity "
               "(ee_vel, for --replay-mode velocity: a robot's force estimate is poor)"},
      {"record-frames", ND_OPT_CHOICE, &c->record_join, .choices = join_words, .arg = "JOIN",
       .def = "cubic; line with --world lab",
       .help = "how --record joins the object's MOCAP frames between their times: a cubic "
               "curve follows the object's acceleration and averages noisy frames' rates "
               "over two frame intervals; a line gives each interval one rate (the lab's fits "
               "were worse with the cubic, doc/decisions.md#frames-per-world)"},
      {"theta", ND_OPT_THETA, c->theta, .def = "the simulation's ground truth, as the planner",
       .help = "theta recorded as the planner's until PARAMS arrives"},
      {"await-fit", ND_OPT_DOUBLE, &c->await_fit, 0.0, 3600.0, .arg = "S",
       .help = "with --record: after appending a task, wait up to S s for PARAMS fitted on it "
               "before going on (the paper's protocol: refit between episodes), after the last "
               "task too; 0: no wait"},
      {"place", ND_OPT_CUSTOM, c, .parse = set_place, .arg = "X,Y,YAW", .def = "",
       .help = "before each task, ask on PLACE for the object at this pose and wait until "
               "MOCAP shows it there (nudge-bridge puts it there once the planner has moved "
               "the sphere clear; on a robot, a person does): every task starts from the same "
               "pose, as the paper's evaluation tasks do"},
      {"park", ND_OPT_LIST, c->park_xy, -NDP_MAX_POS, NDP_MAX_POS, 2, .arg = "X,Y", .def = "",
       .help = "with --place: before each task, once the object is placed, the planner "
               "also takes the sphere round it to this point (m), and the runner waits for it "
               "there (an object moved off the pose before then is placed again): every task "
               "starts from one sphere pose as well as one object pose"},
      {"place-wait", ND_OPT_DOUBLE, &c->place_wait, 0.1, 3600.0, .arg = "S",
       .help = "with --place: how long to wait for the object at the pose before giving up "
               "(status 1)"},
      {"lcm-url", ND_OPT_STRING, &c->url, .arg = "URL", .def = "$LCM_DEFAULT_URL, else " NDP_DEFAULT_URL,
       .help = "LCM URL"},
  };
  nd_opt_spec spec = {
      PROG, "[options]",
      "Run pushing tasks one after another: publish each goal on TASK, follow the object on "
      "MOCAP until the task error L_pos + l1 L_rot falls below eps (reached) or the time limit "
      "passes (timed out), report it on EPISODE and as a line on stdout. Without --place the "
      "object is not reset between tasks: each starts where the last one ended.",
      "Prints one line per task, summary figures as 'name value unit' lines, and ends with\n"
      "'reached K/N goals'. Exit status: 0 every task ran (reached, timed out or rejected),\n"
      "1 the tasks could not be run (no MOCAP, LCM failure), 2 bad arguments, 3 every\n"
      "task ran but appending some to the --record buffer failed (disk full, read-only,\n"
      "I/O error: the tasks go on, each failure is reported, earlier records stay intact),\n"
      "128+n when stopped by signal n (SIGINT: 130), after printing what ran.\n",
      opts, sizeof(opts) / sizeof(opts[0])};
  const int pa = nd_opt_parse(&spec, argc, argv);
  if (pa != ND_OPT_RUN) return pa;
  if (c->await_fit > 0 && !c->record)
    return nd_opt_fail(&spec, "--await-fit needs --record (it waits for the fit of a record)");
  if (nd_opt_find(&spec, "place-wait")->given && !c->place)
    return nd_opt_fail(&spec, "--place-wait needs --place");
  c->park = nd_opt_find(&spec, "park")->given > 0;
  if (c->park && !c->place) return nd_opt_fail(&spec, "--park needs --place");
  if (world == 1 && !nd_opt_find(&spec, "tau")->given) c->tau = 8.0;
  if (world == 1 && !nd_opt_find(&spec, "record-frames")->given)
    c->record_join = ND_REC_JOIN_LINE;
  if (c->n == 0 && world == 1) {
    c->n = (int)(sizeof(chain_lab) / sizeof(chain_lab[0]));
    memcpy(c->goals, chain_lab, sizeof(chain_lab));
  } else if (c->n == 0) {
    c->n = (int)(sizeof(chain) / sizeof(chain[0]));
    memcpy(c->goals, chain, sizeof(chain));
  }
  return ND_OPT_RUN;
}
