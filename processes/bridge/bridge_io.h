/* bridge_io: nudge-bridge's I/O thread and command line (bridge_opts.c): EE_CMD in (validated, checked against the
 * workspace, posted to the loop), ROBOT_STATE and MOCAP out (what the loop left in its
 * ring), and the loop's reports turned into log lines and the heartbeat. */
#ifndef BRIDGE_IO_H
#define BRIDGE_IO_H

#include "bridge_loop.h"
#include "nd_opt.h"
#include "ndp.h"

/* How far beyond its workspace box an EE_CMD position may lie. The executor keeps its
 * trajectories within ND_EXEC_WS_MARGIN of the same box (segment overshoot, brake travel);
 * one more centimetre, so that a setpoint it certified is never refused here, also when
 * the two were given the box in different digits. */
#define BRIDGE_WS_MARGIN 0.05

/* PLACE ids remembered as taken: a sender re-sends its PLACE until it sees the object
 * there, so a re-sent one can arrive after a newer PLACE and must not undo it. */
#define BRIDGE_PLACE_SEEN 8

typedef struct {
  bridge_loop *b;
  nd_box ws;                /* EE_CMD beyond it + BRIDGE_WS_MARGIN is refused */
  ndp_status st;
  ndp_ratelog refused;
  ndp_ratelog refused_ws;   /* valid, but outside the workspace */
  unsigned char buf[ND_RTIO_MAX];  /* one message on its way to LCM */
  bridge_report rep;        /* the newest report */
  int holding;              /* as last said; -1 before */
  int had_cmd;              /* an EE_CMD was tracked before */
  int64_t resets_said, skipped_said, stops_said, silent_said;
  double reset_said_at, skip_said_at, silent_said_at;
  int64_t task_id;          /* the newest TASK seen; -1 none */
  int64_t place_seen[BRIDGE_PLACE_SEEN];  /* the PLACE ids taken, newest at place_next - 1 */
  int place_next;
  int64_t places_said, dropped_said;
  char state[64];           /* the heartbeat's state word ("stopped: joint 4 velocity") */
} bridge_io;

/* The command line. */
typedef struct {
  nds_world_cfg wc;         /* the world */
  nd_rtloop_cfg rt;         /* rate and real-time set-up */
  nd_box ws;                /* workspace box */
  double cmd_timeout;       /* s */
  double seconds;           /* run time; 0: until signalled */
  const char *url;
  nd_opt_spec spec;         /* for refusals after parsing (nd_opt_fail); no table */
} bridge_opts;

/* Parse argv into o (bridge_opts.c). ND_OPT_RUN, or the exit status (usage or refusal
 * printed). */
int bridge_options(int argc, char **argv, bridge_opts *o);

/* Subscribe EE_CMD, TASK and PLACE (a new task or PLACE resumes a stopped arm). Return 0, or
 * -1 with a message. */
int bridge_io_subscribe(bridge_io *io, lcm_t *lcm, char *err, int errlen);

/* Publish what the loop encoded. Return the number of failed publishes. */
int bridge_io_publish(bridge_io *io, lcm_t *lcm);

/* Take the loop's newest report and the loop's statistics: log hold changes, world resets
 * and stalls (each at most once per 5 s), update the heartbeat's state. */
void bridge_io_report(bridge_io *io, uint64_t *version, const nd_rtloop_stats *loop);

#endif
