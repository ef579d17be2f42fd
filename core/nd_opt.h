/* nd_opt: every program's command line, from one table of options, on glibc's getopt_long.
 *
 * A program lists its options once (name, kind, bounds, destination, help); the same table
 * parses argv, prints the usage and, with --list-options, prints itself for tests and
 * shell completion. Every refusal has one form on stderr:
 *
 *   PROG: --name: why          (a bad value; why quotes the value)
 *   PROG: --name needs a value
 *   PROG: unknown argument: WORD
 *
 * followed by "Try 'PROG --help'.", and exit status 2. Destinations hold the defaults
 * when nd_opt_parse is called; the usage shows them. */
#ifndef ND_OPT_H
#define ND_OPT_H

#include <stdint.h>
#include <stdio.h>

#include "nd_parse.h" /* nd_box, the destination of ND_OPT_BOX */

typedef enum {
  ND_OPT_FLAG = 0, /* no value: *(int *)dst = 1 */
  ND_OPT_INT,      /* decimal integer in [lo, hi]: int */
  ND_OPT_U64,      /* unsigned 64-bit decimal: uint64_t */
  ND_OPT_DOUBLE,   /* finite number in [lo, hi]: double */
  ND_OPT_STRING,   /* non-empty text: const char * (points into argv) */
  ND_OPT_LIST,     /* exactly n comma-separated numbers, each in [lo, hi]: double[n] */
  ND_OPT_CHOICE,   /* one word of choices (NULL-terminated): int, the word's index */
  ND_OPT_THETA,    /* theta "S,T,R,M[,B,X,Y]" (nd_theta_parse): double[ND_NTHETA] */
  ND_OPT_BOX,      /* box "XLO,YLO,XHI,YHI" in metres, lo < hi: double[4] */
  ND_OPT_CUSTOM,   /* parse(value, "--name", dst, err, errlen), called for each use */
} nd_opt_kind;

typedef struct {
  const char *name;   /* long name without "--" */
  nd_opt_kind kind;
  void *dst;
  double lo, hi;      /* INT, DOUBLE, LIST bounds */
  int n;              /* LIST: number of values */
  const char *const *choices;  /* CHOICE: accepted words, NULL-terminated */
  int (*parse)(const char *value, const char *what, void *dst, char *err, int errlen);
  const char *arg;    /* the value's name in the usage ("HZ"); NULL: kind's default */
  const char *help;   /* one or more lines ('\n'); wrapped and indented by the usage */
  const char *def;    /* the default as the usage shows it; NULL: printed from *dst; "": none */
  int given;          /* set by nd_opt_parse: how often the option appeared; a later
                         value replaces an earlier one (CUSTOM: parse sees each) */
} nd_opt;

typedef struct {
  const char *prog;     /* "nudge-bridge" */
  const char *synopsis; /* after the program's name on the usage line: "[options]" */
  const char *about;    /* what the program does, before the options */
  const char *epilog;   /* after the options, printed as it is (lines end in '\n'); may be
                           NULL */
  nd_opt *opts;
  int n;
} nd_opt_spec;

/* What nd_opt_parse tells the caller to do next. */
enum { ND_OPT_RUN = -1, ND_OPT_EXIT_OK = 0, ND_OPT_EXIT_BAD = 2 };

/* Parse argv against spec; -h/--help prints the usage on stdout, --list-options the table.
 * Return ND_OPT_RUN to go on, or the exit status (the usage or refusal already printed). */
int nd_opt_parse(nd_opt_spec *spec, int argc, char **argv);

/* Print the usage of spec on f (the defaults as the destinations hold them now). */
void nd_opt_usage(const nd_opt_spec *spec, FILE *f);

/* Refuse the command line after parsing (a rule between options): print "PROG: message"
 * and the hint in the one form above. Return ND_OPT_EXIT_BAD. */
int nd_opt_fail(const nd_opt_spec *spec, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));

/* The entry of spec named name (without "--"), or NULL. */
nd_opt *nd_opt_find(nd_opt_spec *spec, const char *name);

#endif
