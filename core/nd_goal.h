/* nd_goal: a goal pose of the pushed object, and goal lists from the command line or a
 * text file. The one goal type of the project: the planner's cost, the in-process tools
 * and the episode runner all use it.
 *
 * File format, one goal per line:  x y yaw [eps [time_limit]]
 * metres, metres, radians, task-error threshold, seconds; fields separated by blanks or
 * tabs; '#' starts a comment that runs to the end of the line; blank lines are skipped;
 * CRLF line ends are accepted. Every malformed line is an error naming the line. */
#ifndef ND_GOAL_H
#define ND_GOAL_H

#include <stddef.h>

/* Accepted ranges. Positions match ndp_check_task's bound; a |yaw| above 2 pi is refused
 * because it is almost always a value in degrees. */
#define ND_GOAL_MAX_POS 10.0
#define ND_GOAL_MAX_YAW 6.283185307179586
#define ND_GOAL_MAX_TAU 3600.0
#define ND_GOAL_MAX_LINE 1024 /* bytes in one line, comment included */

typedef struct {
  double x, y, yaw; /* goal pose in the table plane: m, m, rad */
  double eps;       /* success threshold; 0: the runner's default */
  double tau;       /* time limit, s; 0: the runner's default */
  int line;         /* 1-based line in its file; 0 for a goal from elsewhere */
} nd_goal;

/* Parse the goal text buf[0..len) (need not be NUL-terminated; any bytes allowed) and
 * append the goals to out[*n..cap), advancing *n. name labels messages ("FILE:LINE: ...").
 * Return 0, or -1 with the first error in err (out[*n..] may hold partial results then).
 * A text without goals is not an error here; the caller decides. */
int nd_goal_list_parse(const char *buf, size_t len, const char *name, nd_goal *out,
                       int cap, int *n, char *err, int errlen);

/* Read and parse file path (at most 1 MiB) as nd_goal_list_parse does. Return 0 or -1. */
int nd_goal_list_load(const char *path, nd_goal *out, int cap, int *n, char *err, int errlen);

/* Parse one goal "X,Y,YAW[,EPS[,TIME_LIMIT]]" (a command line's) into *g. Return 0, or -1
 * with a message quoting s. */
int nd_goal_parse_arg(const char *s, nd_goal *g, char *err, int errlen);

#endif
