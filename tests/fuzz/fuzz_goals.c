/* Fuzz target: goal lists (processes/nd_goal.h), the one text format a user hands the
 * system.
 *
 * The input is the text of a goal file. Parsing must return 0 or -1 with a message that
 * names the file and line, never write beyond the output array, and accept only goals
 * inside the documented ranges, numbered by strictly increasing lines. An accepted list
 * printed back with %.17g must parse to the same numbers bit for bit. The same bytes (up
 * to the first NUL) also go through the command-line form X,Y,YAW[,EPS[,TIME_LIMIT]]. */
#include <math.h>
#include <string.h>

#include "fuzz.h"
#include "nd_goal.h"

#define FZ_CAP 8  /* small, so that "more than cap goals" is reachable */

static void fz_goal_ok(const nd_goal *g) {
  FZ_CHECK(isfinite(g->x) && fabs(g->x) <= ND_GOAL_MAX_POS && isfinite(g->y) &&
           fabs(g->y) <= ND_GOAL_MAX_POS && isfinite(g->yaw) &&
           fabs(g->yaw) <= ND_GOAL_MAX_YAW, "goal (%g, %g, %g) out of range", g->x, g->y,
           g->yaw);
  /* 0 means "the runner's default"; a given value is in range. */
  FZ_CHECK(g->eps == 0 || (g->eps > 0 && g->eps <= 1.0), "eps %g", g->eps);
  FZ_CHECK(g->tau == 0 || (g->tau > 0 && g->tau <= ND_GOAL_MAX_TAU), "tau %g", g->tau);
  FZ_CHECK(g->tau == 0 || g->eps != 0, "a time limit without eps cannot be written");
}

static int fz_same(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

/* The command-line form on the same bytes (a C string ends at the first NUL). */
static void fz_arg(const uint8_t *data, size_t size) {
  char arg[300], err[512];
  const size_t alen = size < sizeof arg - 1 ? size : sizeof arg - 1;
  memcpy(arg, data, alen);
  arg[alen] = 0;
  nd_goal g;
  if (nd_goal_parse_arg(arg, &g, err, sizeof err) == 0) {
    fz_goal_ok(&g);
    FZ_CHECK(g.line == 0, "command-line goal has line %d", g.line);
  } else {
    /* The message quotes what it refuses (or says what a goal is, for one too long). */
    FZ_CHECK(err[0] == '\'' || strncmp(err, "expected", 8) == 0,
             "message does not quote the goal: %.80s", err);
  }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fz_arg(data, size);
  nd_goal out[FZ_CAP + 1];
  memset(out, 0xA5, sizeof out);
  const nd_goal guard = out[FZ_CAP];
  char err[512];
  int n = 0;
  const int rc = nd_goal_list_parse((const char *)data, size, "fz.goals", out, FZ_CAP, &n, err,
                                 sizeof err);
  FZ_CHECK(rc == 0 || rc == -1, "rc %d", rc);
  FZ_CHECK(n >= 0 && n <= FZ_CAP, "n = %d", n);
  FZ_CHECK(memcmp(&out[FZ_CAP], &guard, sizeof guard) == 0, "wrote past cap");
  if (rc) {
    FZ_CHECK(memchr(err, 0, sizeof err) && strncmp(err, "fz.goals:", 9) == 0,
             "message does not name the file: %.80s", err);
    return 0;
  }
  for (int i = 0; i < n; i++) {
    fz_goal_ok(&out[i]);
    FZ_CHECK(out[i].line >= 1 && (i == 0 || out[i].line > out[i - 1].line), "line %d",
             out[i].line);
  }

  /* Print back and parse again: the same goals, bit for bit. */
  static char text[FZ_CAP * 256];  /* a line is at most 5 x 24 + 5 bytes */
  size_t len = 0;
  for (int i = 0; i < n; i++) {
    const nd_goal *g = &out[i];
    len += (size_t)snprintf(text + len, sizeof text - len, "%.17g %.17g %.17g", g->x, g->y,
                            g->yaw);
    if (g->eps != 0) len += (size_t)snprintf(text + len, sizeof text - len, " %.17g", g->eps);
    if (g->tau != 0) len += (size_t)snprintf(text + len, sizeof text - len, " %.17g", g->tau);
    len += (size_t)snprintf(text + len, sizeof text - len, "\n");
  }
  FZ_CHECK(len < sizeof text, "printed goals truncated");
  nd_goal back[FZ_CAP];
  int m = 0;
  FZ_CHECK(nd_goal_list_parse(text, len, "printed", back, FZ_CAP, &m, err, sizeof err) == 0,
           "printed goals refused: %s", err);
  FZ_CHECK(m == n, "%d goals printed, %d parsed back", n, m);
  for (int i = 0; i < n; i++)
    FZ_CHECK(fz_same(back[i].x, out[i].x) && fz_same(back[i].y, out[i].y) &&
             fz_same(back[i].yaw, out[i].yaw) && fz_same(back[i].eps, out[i].eps) &&
             fz_same(back[i].tau, out[i].tau) && back[i].line == i + 1,
             "goal %d changed in the round trip", i);
  return 0;
}
