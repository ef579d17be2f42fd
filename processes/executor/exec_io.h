/* exec_io: nudge-executor's I/O thread and command line (exec_opts.c): LCM in (ROBOT_STATE, PLAN validated and posted to
 * the loop's mailboxes), EE_CMD out (what the loop left in its ring), and what the loop
 * reports turned into log lines and the heartbeat. */
#ifndef EXEC_IO_H
#define EXEC_IO_H

#include "exec_loop.h"
#include "nd_opt.h"
#include "ndp.h"

typedef struct {
  exec_loop_io *x;     /* the loop's mailboxes and ring */
  double timeout, plan_timeout;  /* s: the loop's, for log lines */
  ndp_status st;
  int backlog_max;     /* most setpoints found waiting in the ring at once */
  ndp_ratelog log_state, log_plan, log_exec;  /* refused inputs; plans nd_exec refused */
  ndp_ratelog log_box;                        /* of those: for the workspace */
  ndp_ratelog log_old;                        /* plans made from a state too old */
  exec_loop_report last;                      /* the report taken last */
} exec_io;

/* The command line. */
typedef struct {
  nd_exec_cfg cfg;      /* limits and workspace */
  nd_rtloop_cfg rt;     /* rate and real-time set-up */
  double timeout;       /* s: robot state older than this is stale */
  double plan_timeout;  /* s: a plan older than this is stale */
  const char *url;
} exec_opts;

/* Parse argv into o (exec_opts.c). ND_OPT_RUN, or the exit status (usage or refusal
 * printed). */
int exec_options(int argc, char **argv, exec_opts *o);

/* Subscribe ROBOT_STATE and PLAN for io on lcm. Return 0, or -1 with a message. */
int exec_io_subscribe(exec_io *io, lcm_t *lcm, char *err, int errlen);

/* Publish what the loop committed, oldest first. Return the number published, -1 on a
 * publish error. */
int exec_io_publish(exec_io *io, lcm_t *lcm);

/* Take the loop's newest report, if any: log stale transitions and refused plans new
 * since the last one, update the heartbeat's state and refusals. Return 1 if taken. */
int exec_io_report(exec_io *io, uint64_t *version);

#endif
