/* nd_goal: goal lists from text. The parser works on a byte buffer of known length so
 * that it can be fed anything (files with NULs, no final newline, a fuzzer's bytes). */
#include "nd_goal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nd_math.h"
#include "nd_parse.h"

#define MAX_FIELDS 5
#define MAX_FILE (1 << 20)

static const char *field_name[MAX_FIELDS] = {"x", "y", "yaw", "eps", "time_limit"};

static int is_blank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* Check and convert field i of a goal. 0, or -1 with a message without location. */
static int parse_field(int i, const char *tok, double *out, char *msg, int len) {
  for (const unsigned char *p = (const unsigned char *)tok; *p; p++)
    if (*p < 0x20 || *p == 0x7f) {
      snprintf(msg, len, "%s contains the control byte 0x%02x", field_name[i], *p);
      return -1;
    }
  /* Range checks are ours so that the messages can say what the range means. */
  if (nd_parse_double(tok, field_name[i], -HUGE_VAL, HUGE_VAL, out, msg, len)) return -1;
  const double v = *out;
  switch (i) {
    case 0:
    case 1:
      if (fabs(v) > ND_GOAL_MAX_POS) {
        snprintf(msg, len, "%s = %g m is beyond %g m", field_name[i], v, ND_GOAL_MAX_POS);
        return -1;
      }
      return 0;
    case 2:
      if (fabs(v) > ND_GOAL_MAX_YAW) {
        snprintf(msg, len, "yaw = %g is beyond 2 pi: yaw is in radians (%g deg = %.4f rad)",
                 v, v, v * ND_PI / 180.0);
        return -1;
      }
      return 0;
    case 3:
      if (!(v > 0.0 && v <= 1.0)) {
        snprintf(msg, len, "eps = %g is outside (0, 1]", v);
        return -1;
      }
      return 0;
    default:
      if (!(v > 0.0 && v <= ND_GOAL_MAX_TAU)) {
        snprintf(msg, len, "time_limit = %g s is outside (0, %g]", v, ND_GOAL_MAX_TAU);
        return -1;
      }
      return 0;
  }
}

/* Parse the fields of one goal, already split, into g. 0, or -1 with a message. */
static int parse_fields(char **tok, int nf, nd_goal *g, char *msg, int len) {
  double v[MAX_FIELDS] = {0};
  for (int i = 0; i < nf; i++)
    if (parse_field(i, tok[i], &v[i], msg, len)) return -1;
  g->x = v[0];
  g->y = v[1];
  g->yaw = v[2];
  g->eps = v[3];
  g->tau = v[4];
  return 0;
}

int nd_goal_list_parse(const char *buf, size_t len, const char *name, nd_goal *out, int cap,
                    int *n, char *err, int errlen) {
  char line[ND_GOAL_MAX_LINE + 1];
  char msg[256];
  size_t pos = 0;
  int lineno = 0;
  if (!name) name = "goals";
  while (pos < len) {
    lineno++;
    const char *start = buf + pos;
    const char *nl = memchr(start, '\n', len - pos);
    const size_t ll = nl ? (size_t)(nl - start) : len - pos;
    pos += ll + (nl ? 1 : 0);
    if (ll > ND_GOAL_MAX_LINE) {
      snprintf(err, errlen, "%s:%d: line is longer than %d bytes", name, lineno,
               ND_GOAL_MAX_LINE);
      return -1;
    }
    if (memchr(start, '\0', ll)) {
      snprintf(err, errlen, "%s:%d: contains a NUL byte (not a text file?)", name, lineno);
      return -1;
    }
    memcpy(line, start, ll);
    line[ll] = '\0';
    char *hash = strchr(line, '#');
    if (hash) *hash = '\0';

    char *tok[MAX_FIELDS + 1];
    int nf = 0;
    for (char *p = line; *p;) {
      while (is_blank(*p)) *p++ = '\0';
      if (!*p) break;
      if (nf <= MAX_FIELDS) tok[nf] = p;
      nf++;
      while (*p && !is_blank(*p)) p++;
    }
    if (nf == 0) continue;
    if (nf < 3 || nf > MAX_FIELDS) {
      snprintf(err, errlen, "%s:%d: %d field%s, expected 'x y yaw [eps [time_limit]]'", name,
               lineno, nf, nf == 1 ? "" : "s");
      return -1;
    }
    if (*n >= cap) {
      snprintf(err, errlen, "%s:%d: more than %d goals", name, lineno, cap);
      return -1;
    }
    nd_goal *g = &out[*n];
    if (parse_fields(tok, nf, g, msg, sizeof(msg))) {
      snprintf(err, errlen, "%s:%d: %s", name, lineno, msg);
      return -1;
    }
    g->line = lineno;
    (*n)++;
  }
  return 0;
}

int nd_goal_list_load(const char *path, nd_goal *out, int cap, int *n, char *err, int errlen) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    snprintf(err, errlen, "cannot open %s: %s", path, strerror(errno));
    return -1;
  }
  char *buf = malloc(MAX_FILE + 1);
  if (!buf) {
    fclose(f);
    snprintf(err, errlen, "out of memory reading %s", path);
    return -1;
  }
  const size_t len = fread(buf, 1, MAX_FILE + 1, f);
  int rc = -1;
  if (ferror(f))
    snprintf(err, errlen, "cannot read %s: %s", path, strerror(errno));
  else if (len > MAX_FILE)
    snprintf(err, errlen, "%s is larger than %d bytes: not a goal list?", path, MAX_FILE);
  else
    rc = nd_goal_list_parse(buf, len, path, out, cap, n, err, errlen);
  free(buf);
  fclose(f);
  return rc;
}

int nd_goal_parse_arg(const char *s, nd_goal *g, char *err, int errlen) {
  char buf[256], msg[256];
  if (!s || strlen(s) >= sizeof(buf)) {
    snprintf(err, errlen, "expected X,Y,YAW (m, m, rad)");
    return -1;
  }
  strcpy(buf, s);
  char *tok[MAX_FIELDS];
  int nf = 0;
  for (char *p = buf;; p++) {
    if (nf < MAX_FIELDS) tok[nf] = p;
    nf++;
    p = strchr(p, ',');
    if (!p) break;
    *p = '\0';
  }
  if (nf < 3 || nf > MAX_FIELDS) {
    snprintf(err, errlen, "'%s': expected X,Y,YAW[,EPS[,TIME_LIMIT]] (m, m, rad)", s);
    return -1;
  }
  if (parse_fields(tok, nf, g, msg, sizeof(msg))) {
    snprintf(err, errlen, "'%s': %s", s, msg);
    return -1;
  }
  g->line = 0;
  return 0;
}
