/* ndp_goals: goal lists for the episode runner, from the command line or a text file.
 *
 * File format, one goal per line:  x y yaw [eps [time_limit]]
 * metres, metres, radians, task-error threshold, seconds; fields separated by blanks or
 * tabs; '#' starts a comment that runs to the end of the line; blank lines are skipped;
 * CRLF line ends are accepted. Every malformed line is an error naming the line. */
#ifndef NDP_GOALS_H
#define NDP_GOALS_H

#include <stddef.h>

/* Accepted ranges. Positions match ndp_check_task's bound; a |yaw| above 2 pi is refused
 * because it is almost always a value in degrees. */
#define NDP_GOAL_MAX_POS 10.0
#define NDP_GOAL_MAX_YAW 6.283185307179586
#define NDP_GOAL_MAX_TAU 3600.0
#define NDP_GOAL_MAX_LINE 1024 /* bytes in one line, comment included */

typedef struct {
  double x, y, yaw; /* goal pose: m, m, rad */
  double eps;       /* success threshold; 0: the runner's default */
  double tau;       /* time limit, s; 0: the runner's default */
  int line;         /* 1-based line in its file; 0 for a goal from the command line */
} ndp_goal;

/* Parse the goal text buf[0..len) (need not be NUL-terminated; any bytes allowed) and
 * append the goals to out[*n..cap), advancing *n. name labels messages ("FILE:LINE: ...").
 * Return 0, or -1 with the first error in err (out[*n..] may hold partial results then).
 * A text without goals is not an error here; the caller decides. */
int ndp_goals_parse(const char *buf, size_t len, const char *name, ndp_goal *out, int cap,
                    int *n, char *err, int errlen);

/* Read and parse file path (at most 1 MiB) as ndp_goals_parse does. Return 0 or -1. */
int ndp_goals_load(const char *path, ndp_goal *out, int cap, int *n, char *err, int errlen);

/* Parse one command-line goal "X,Y,YAW" into *g (eps, tau 0). Return 0, or -1. */
int ndp_goal_parse_arg(const char *s, ndp_goal *g, char *err, int errlen);

#endif
