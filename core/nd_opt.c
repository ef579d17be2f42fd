/* nd_opt: the option table, getopt_long over it, and the usage printed from it. */
#define _GNU_SOURCE
#include "nd_opt.h"

#include <getopt.h>
#include <inttypes.h>
#include <stdarg.h>
#include <string.h>

#include "nd_parse.h"
#include "nd_theta.h"

#define MAX_OPTS 64
#define WIDTH 88  /* usage lines wrap here */
#define COL 22    /* help text starts in this column */
#define BOX_MAX 10.0  /* m: a workspace box lies within +-10 m, as every position a process takes */

/* getopt_long's val for entry i; below it 'h' and the table listing. */
enum { VAL_LIST = 255, VAL_BASE = 256 };

static const char *kind_name[] = {"flag", "int", "u64", "double", "string",
                                  "list", "choice", "theta", "box", "custom"};

static const char *default_arg(const nd_opt *o) {
  switch (o->kind) {
    case ND_OPT_INT:
    case ND_OPT_U64: return "N";
    case ND_OPT_DOUBLE: return "X";
    case ND_OPT_THETA: return "S,T,R,M[,B,X,Y]";
    case ND_OPT_BOX: return "XLO,YLO,XHI,YHI";
    case ND_OPT_CHOICE: return "WORD";
    case ND_OPT_LIST: return "X,...";
    default: return "VALUE";
  }
}

static int has_value(const nd_opt *o) { return o->kind != ND_OPT_FLAG; }

/* The current value of *o->dst as text (the default, before parsing); "" if none. */
static void value_str(const nd_opt *o, char *buf, int len) {
  buf[0] = '\0';
  const double *d = o->dst;
  switch (o->kind) {
    case ND_OPT_INT: snprintf(buf, len, "%d", *(const int *)o->dst); break;
    case ND_OPT_U64: snprintf(buf, len, "%" PRIu64, *(const uint64_t *)o->dst); break;
    case ND_OPT_DOUBLE: snprintf(buf, len, "%g", *d); break;
    case ND_OPT_STRING: {
      const char *s = *(const char *const *)o->dst;
      snprintf(buf, len, "%s", s ? s : "");
      break;
    }
    case ND_OPT_CHOICE: {
      const int i = *(const int *)o->dst;
      snprintf(buf, len, "%s", i >= 0 ? o->choices[i] : "");
      break;
    }
    case ND_OPT_LIST:
    case ND_OPT_THETA: {
      const int n = o->kind == ND_OPT_LIST ? o->n : ND_NTHETA;
      int at = 0;
      for (int i = 0; i < n && at < len; i++) at += snprintf(buf + at, len - at, "%s%g", i ? "," : "", d[i]);
      break;
    }
    case ND_OPT_BOX: {
      const nd_box *b = o->dst;
      snprintf(buf, len, "%g,%g,%g,%g", b->lo[0], b->lo[1], b->hi[0], b->hi[1]);
      break;
    }
    default: break;
  }
}

/* Print text on f starting at column col (the cursor is there), wrapped at WIDTH with
 * continuation lines indented to col; '\n' in text breaks a line. */
static void wrap(FILE *f, const char *text, int col) {
  int at = col;
  const char *p = text;
  while (*p) {
    if (*p == '\n') {
      fprintf(f, "\n%*s", col, "");
      at = col;
      p++;
      continue;
    }
    if (*p == ' ') {
      p++;
      continue;
    }
    const size_t w = strcspn(p, " \n");
    if (at > col && at + 1 + (int)w > WIDTH) {
      fprintf(f, "\n%*s", col, "");
      at = col;
    } else if (at > col) {
      fputc(' ', f);
      at++;
    }
    fwrite(p, 1, w, f);
    at += (int)w;
    p += w;
  }
}

void nd_opt_usage(const nd_opt_spec *spec, FILE *f) {
  fprintf(f, "usage: %s %s\n", spec->prog, spec->synopsis ? spec->synopsis : "[options]");
  if (spec->about) {
    wrap(f, spec->about, 0);
    fputc('\n', f);
  }
  fputc('\n', f);
  for (int i = 0; i < spec->n; i++) {
    const nd_opt *o = &spec->opts[i];
    char head[96], def[200], help[1200];
    int n = snprintf(head, sizeof head, "  --%s%s%s", o->name, has_value(o) ? " " : "",
                     has_value(o) ? (o->arg ? o->arg : default_arg(o)) : "");
    fputs(head, f);
    if (n >= COL - 1)
      fprintf(f, "\n%*s", COL, "");
    else
      fprintf(f, "%*s", COL - n, "");
    if (o->def) snprintf(def, sizeof def, "%s", o->def);
    else value_str(o, def, sizeof def);
    char range[80] = "";
    if (o->kind == ND_OPT_INT || o->kind == ND_OPT_DOUBLE)
      snprintf(range, sizeof range, "%g..%g%s", o->lo, o->hi, def[0] ? ", " : "");
    snprintf(help, sizeof help, "%s%s%s%s%s%s", o->help ? o->help : "",
             range[0] || def[0] ? " (" : "", range, def[0] ? "default " : "", def,
             range[0] || def[0] ? ")" : "");
    wrap(f, help, COL);
    fputc('\n', f);
  }
  fputs("  --list-options      the options as a table (name, kind, bounds, default), for scripts\n"
        "  -h, --help          this text\n", f);
  if (spec->epilog) fprintf(f, "\n%s", spec->epilog);
}

/* One line per option, tab-separated: name, kind, lo, hi, n, default, choices ("-" for
 * none). test_cli builds its cases from this. */
static void list_options(const nd_opt_spec *spec) {
  for (int i = 0; i < spec->n; i++) {
    const nd_opt *o = &spec->opts[i];
    char def[200], ch[200] = "-";
    value_str(o, def, sizeof def);
    if (o->kind == ND_OPT_CHOICE) {
      int at = 0;
      for (int k = 0; o->choices[k]; k++)
        at += snprintf(ch + at, sizeof ch - at, "%s%s", k ? "," : "", o->choices[k]);
    }
    const int bounded = o->kind == ND_OPT_INT || o->kind == ND_OPT_DOUBLE || o->kind == ND_OPT_LIST;
    printf("--%s\t%s\t%.15g\t%.15g\t%d\t%s\t%s\n", o->name, kind_name[o->kind],
           bounded ? o->lo : 0.0, bounded ? o->hi : 0.0, o->kind == ND_OPT_LIST ? o->n : 0,
           def[0] ? def : "-", ch);
  }
}

static void vfail(const nd_opt_spec *spec, const char *fmt, va_list ap) {
  fprintf(stderr, "%s: ", spec->prog);
  vfprintf(stderr, fmt, ap);
  fprintf(stderr, "\nTry '%s --help'.\n", spec->prog);
}

int nd_opt_fail(const nd_opt_spec *spec, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vfail(spec, fmt, ap);
  va_end(ap);
  return ND_OPT_EXIT_BAD;
}

nd_opt *nd_opt_find(nd_opt_spec *spec, const char *name) {
  for (int i = 0; i < spec->n; i++)
    if (!strcmp(spec->opts[i].name, name)) return &spec->opts[i];
  return NULL;
}

/* Parse value v of option o (named what, "--name") into its destination. */
static int take(nd_opt *o, const char *what, const char *v, char *err, int errlen) {
  switch (o->kind) {
    case ND_OPT_FLAG: *(int *)o->dst = 1; return 0;
    case ND_OPT_INT: return nd_parse_int(v, what, (long)o->lo, (long)o->hi, o->dst, err, errlen);
    case ND_OPT_U64: return nd_parse_u64(v, what, o->dst, err, errlen);
    case ND_OPT_DOUBLE: return nd_parse_double(v, what, o->lo, o->hi, o->dst, err, errlen);
    case ND_OPT_LIST: {
      double tmp[16];
      if (o->n > 16 || nd_parse_list(v, what, o->n, o->lo, o->hi, tmp, err, errlen)) return -1;
      memcpy(o->dst, tmp, sizeof(double) * o->n);
      return 0;
    }
    case ND_OPT_THETA: return nd_theta_parse(v, what, o->dst, err, errlen);
    case ND_OPT_BOX: return nd_parse_box(v, what, BOX_MAX, o->dst, err, errlen);
    case ND_OPT_STRING:
      if (!*v) {
        snprintf(err, errlen, "%s: empty value", what);
        return -1;
      }
      *(const char **)o->dst = v;
      return 0;
    case ND_OPT_CHOICE:
      for (int k = 0; o->choices[k]; k++)
        if (!strcmp(v, o->choices[k])) {
          *(int *)o->dst = k;
          return 0;
        }
      {
        char words[200] = "";
        int at = 0;
        for (int k = 0; o->choices[k]; k++)
          at += snprintf(words + at, sizeof words - at, "%s%s", k ? ", " : "", o->choices[k]);
        snprintf(err, errlen, "%s: '%.60s' is not one of %s", what, v, words);
      }
      return -1;
    case ND_OPT_CUSTOM: return o->parse(v, what, o->dst, err, errlen);
  }
  return -1;
}

/* The argv element that named option i (name or "--name=value"), given where getopt_long
 * left optind: getopt never abbreviates here, so the element must spell the name out. */
static const char *element(char **argv, const nd_opt *o) {
  const char *last = argv[optind - 1];
  if (has_value(o) && optarg == last) return argv[optind - 2];
  return last;
}

int nd_opt_parse(nd_opt_spec *spec, int argc, char **argv) {
  struct option lo[MAX_OPTS + 3];
  char err[512];
  if (spec->n > MAX_OPTS) return nd_opt_fail(spec, "internal: more than %d options", MAX_OPTS);
  for (int i = 0; i < spec->n; i++) {
    lo[i].name = spec->opts[i].name;
    lo[i].has_arg = has_value(&spec->opts[i]) ? required_argument : no_argument;
    lo[i].flag = NULL;
    lo[i].val = VAL_BASE + i;
    spec->opts[i].given = 0;
  }
  lo[spec->n] = (struct option){"help", no_argument, NULL, 'h'};
  lo[spec->n + 1] = (struct option){"list-options", no_argument, NULL, VAL_LIST};
  lo[spec->n + 2] = (struct option){NULL, 0, NULL, 0};

  /* "+": stop at the first word that is not an option (no program takes any, and a word
   * must not be moved behind the options it came before); ":": tell a missing value apart.
   * optind 0 makes glibc start over, so a program may parse twice. */
  opterr = 0;
  optind = 0;
  for (;;) {
    const int c = getopt_long(argc, argv, "+:h", lo, NULL);
    if (c == -1) break;
    if (c == 'h') {
      nd_opt_usage(spec, stdout);
      return ND_OPT_EXIT_OK;
    }
    if (c == VAL_LIST) {
      list_options(spec);
      return ND_OPT_EXIT_OK;
    }
    if (c == ':') {
      const int i = optopt - VAL_BASE;
      if (i >= 0 && i < spec->n) return nd_opt_fail(spec, "--%s needs a value", spec->opts[i].name);
      return nd_opt_fail(spec, "unknown argument: %s", argv[optind - 1]);
    }
    if (c == '?') {
      const int i = optopt - VAL_BASE;
      if (optopt == 'h' || optopt == VAL_LIST || (i >= 0 && i < spec->n))
        return nd_opt_fail(spec, "%s: the option takes no value", argv[optind - 1]);
      if (optopt > 0 && optopt < 128) return nd_opt_fail(spec, "unknown argument: -%c", optopt);
      return nd_opt_fail(spec, "unknown argument: %s", argv[optind - 1]);
    }
    nd_opt *o = &spec->opts[c - VAL_BASE];
    const char *el = element(argv, o);
    const size_t len = strlen(o->name);
    if (strncmp(el, "--", 2) || strncmp(el + 2, o->name, len) || (el[2 + len] && el[2 + len] != '='))
      return nd_opt_fail(spec, "unknown argument: %s (options are not abbreviated: --%s?)", el,
                         o->name);
    o->given++;
    char what[80];
    snprintf(what, sizeof what, "--%s", o->name);
    if (take(o, what, optarg, err, sizeof err)) return nd_opt_fail(spec, "%s", err);
  }
  if (optind < argc) return nd_opt_fail(spec, "unknown argument: %s", argv[optind]);
  return ND_OPT_RUN;
}
