/* test_opt: the option table parser (core/nd_opt.c): every kind's values, the one form of
 * refusal, defaults kept, later values winning, no abbreviations, the usage and the
 * table printed from the same table. */
#define _GNU_SOURCE
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "nd_test.h"
#include "nd_opt.h"
#include "nd_parse.h"
#include "nd_theta.h"

typedef struct {
  int n, flag, choice;
  uint64_t seed;
  double x, list[3], theta[ND_NTHETA];
  nd_box box;
  const char *name;
  int customs;
} cfg;

static const char *const words[] = {"force", "velocity", "setpoint", NULL};

static int count_custom(const char *v, const char *what, void *dst, char *err, int errlen) {
  if (strcmp(v, "ok")) {
    snprintf(err, errlen, "%s: '%s' is not ok", what, v);
    return -1;
  }
  ((cfg *)dst)->customs++;
  return 0;
}

static cfg g;
static nd_opt g_opts[9];
static nd_opt_spec g_spec;

static void setup_table(void) {
  memset(&g, 0, sizeof g);
  g.n = 7, g.x = 0.5, g.seed = 3, g.choice = 2;
  memcpy(g.theta, nd_theta_true, sizeof g.theta);
  g.box = (nd_box){{-1, -1}, {1, 1}};
  const nd_opt t[] = {
      {"n", ND_OPT_INT, &g.n, 1, 10, .help = "a count"},
      {"x", ND_OPT_DOUBLE, &g.x, 0, 1, .arg = "S", .help = "a fraction"},
      {"seed", ND_OPT_U64, &g.seed, .help = "a seed"},
      {"list", ND_OPT_LIST, g.list, -2, 2, 3, .help = "three numbers"},
      {"theta", ND_OPT_THETA, g.theta, .help = "model parameters"},
      {"box", ND_OPT_BOX, &g.box, .help = "a box"},
      {"mode", ND_OPT_CHOICE, &g.choice, .choices = words, .help = "a word"},
      {"name", ND_OPT_STRING, &g.name, .help = "a name"},
      {"flag", ND_OPT_FLAG, &g.flag, .help = "a switch"},
  };
  memcpy(g_opts, t, sizeof t);
  g_spec = (nd_opt_spec){"nd-test", "[options]", "Tests the parser.", "Epilog line.\n", g_opts, 9};
}

/* Run the parser on the words of args (space-separated), capturing stdout and stderr. */
static int run(const char *args, char *out, char *errs, size_t cap) {
  static char buf[512]; /* argv points into it after the call: ND_OPT_STRING keeps it */
  char *argv[32];
  int argc = 0;
  argv[argc++] = "nd-test";
  snprintf(buf, sizeof buf, "%s", args);
  for (char *p = strtok(buf, " "); p && argc < 31; p = strtok(NULL, " "))
    argv[argc++] = strcmp(p, "''") ? p : "";
  argv[argc] = NULL;
  fflush(stdout);
  fflush(stderr);
  FILE *fo = tmpfile(), *fe = tmpfile();
  const int so = dup(1), se = dup(2);
  dup2(fileno(fo), 1);
  dup2(fileno(fe), 2);
  const int rc = nd_opt_parse(&g_spec, argc, argv);
  fflush(stdout);
  fflush(stderr);
  dup2(so, 1);
  dup2(se, 2);
  close(so);
  close(se);
  rewind(fo);
  rewind(fe);
  out[fread(out, 1, cap - 1, fo)] = '\0';
  errs[fread(errs, 1, cap - 1, fe)] = '\0';
  fclose(fo);
  fclose(fe);
  return rc;
}

static void test_values(void **state) {
  (void)state;
  char out[8192], err[8192];
  setup_table();
  assert_int_equal(run("", out, err, sizeof out), ND_OPT_RUN);
  assert_int_equal(g.n, 7);  /* defaults stay */
  assert_near(g.x, 0.5, 0);
  assert_int_equal(g_opts[0].given, 0);
  assert_int_equal(run("--n 3 --x=0.25 --seed 18446744073709551615 --list 1,-2,0.5 "
                       "--theta 0.3,0.005,1e-4,50 --box -0.4,-0.3,0.4,0.3 --mode velocity "
                       "--name abc --flag",
                       out, err, sizeof out),
                   ND_OPT_RUN);
  assert_string_equal(err, "");
  assert_int_equal(g.n, 3);
  assert_near(g.x, 0.25, 0);
  assert_true(g.seed == UINT64_MAX);
  assert_near(g.list[1], -2, 0);
  assert_near(g.theta[ND_TH_MASS], 50, 0);
  assert_near(g.box.lo[1], -0.3, 0);
  assert_near(g.box.hi[0], 0.4, 0);
  assert_int_equal(g.choice, 1);
  assert_string_equal(g.name, "abc");
  assert_int_equal(g.flag, 1);
  for (int i = 0; i < 9; i++) assert_int_equal(g_opts[i].given, 1);
  /* A later value replaces an earlier one. */
  assert_int_equal(run("--n 3 --n 9", out, err, sizeof out), ND_OPT_RUN);
  assert_int_equal(g.n, 9);
  assert_int_equal(g_opts[0].given, 2);
}

static void test_custom(void **state) {
  (void)state;
  char out[4096], err[4096];
  setup_table();
  nd_opt t[] = {{"goal", ND_OPT_CUSTOM, &g, .parse = count_custom, .help = "repeatable"}};
  nd_opt_spec spec = {"nd-test", "", NULL, NULL, t, 1};
  g_spec = spec;
  assert_int_equal(run("--goal ok --goal ok --goal ok", out, err, sizeof out), ND_OPT_RUN);
  assert_int_equal(g.customs, 3);
  assert_int_equal(t[0].given, 3);
  assert_int_equal(run("--goal bad", out, err, sizeof out), ND_OPT_EXIT_BAD);
  assert_non_null(strstr(err, "nd-test: --goal: 'bad' is not ok\n"));
}

/* One form of refusal for every way a command line goes wrong; nothing half-parsed is kept
 * meaningful (the caller exits 2). */
static void test_refusals(void **state) {
  (void)state;
  static const struct {
    const char *args, *first_line;
  } cases[] = {
      {"--n 11", "nd-test: --n: 11 is out of range [1, 10]"},
      {"--n 1.5", "nd-test: --n: '1.5' is not an integer"},
      {"--n ''", "nd-test: --n: empty value"},
      {"--x nan", "nd-test: --x: 'nan' is not a finite number"},
      {"--x 2", "nd-test: --x: 2 is out of range [0, 1]"},
      {"--seed -1", "nd-test: --seed: '-1' is not a non-negative integer"},
      {"--list 1,2", "nd-test: --list: expected 3 comma-separated numbers, got '1,2'"},
      {"--theta 1,0.005,0.0001,0", "nd-test: --theta: theta[3] (sphere mass) = 0"},
      {"--box 1,0,0,1", "nd-test: --box: '1,0,0,1' is not a box"},
      {"--mode fast", "nd-test: --mode: 'fast' is not one of force, velocity, setpoint"},
      {"--name ''", "nd-test: --name: empty value"},
      {"--n", "nd-test: --n needs a value"},
      {"--flag=1", "nd-test: --flag=1: the option takes no value"},
      {"--help=1", "nd-test: --help=1: the option takes no value"},
      {"--bogus", "nd-test: unknown argument: --bogus"},
      {"-q", "nd-test: unknown argument: -q"},
      {"stray", "nd-test: unknown argument: stray"},
      {"--n 2 -- word", "nd-test: unknown argument: word"},
      {"--se 4", "nd-test: unknown argument: --se (options are not abbreviated: --seed?)"},
      {"--thet=1,1,1,1", "nd-test: unknown argument: --thet=1,1,1,1"},
  };
  char out[4096], err[4096];
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
    setup_table();
    const int rc = run(cases[i].args, out, err, sizeof out);
    if (rc != ND_OPT_EXIT_BAD || strncmp(err, cases[i].first_line, strlen(cases[i].first_line)) ||
        !strstr(err, "\nTry 'nd-test --help'.\n") || out[0])
      fail_msg("'%s': rc %d, stderr '%s', stdout '%s'", cases[i].args, rc, err, out);
  }
  setup_table();
  assert_int_equal(nd_opt_fail(&g_spec, "rule %d broken", 4), ND_OPT_EXIT_BAD);
}

/* The usage and the table come from the same table: every option, its value's name, its
 * range and its default; -h prints on stdout and exits 0. */
static void test_usage_and_table(void **state) {
  (void)state;
  char out[8192], err[8192];
  setup_table();
  assert_int_equal(run("-h", out, err, sizeof out), ND_OPT_EXIT_OK);
  assert_string_equal(err, "");
  assert_int_equal(strncmp(out, "usage: nd-test [options]\nTests the parser.\n", 43), 0);
  for (int i = 0; i < 9; i++) {
    char name[40];
    snprintf(name, sizeof name, "  --%s", g_opts[i].name);
    assert_non_null(strstr(out, name));
  }
  assert_non_null(strstr(out, "--x S"));
  assert_non_null(strstr(out, "a count (1..10, default 7)"));
  assert_non_null(strstr(out, "(default 1,0.005,0.0001,1,1,0,0)"));
  assert_non_null(strstr(out, "(default setpoint)"));
  assert_non_null(strstr(out, "-h, --help"));
  assert_non_null(strstr(out, "\nEpilog line.\n"));
  assert_int_equal(run("--list-options", out, err, sizeof out), ND_OPT_EXIT_OK);
  assert_non_null(strstr(out, "--n\tint\t1\t10\t0\t7\t-\n"));
  assert_non_null(strstr(out, "--list\tlist\t-2\t2\t3\t0,0,0\t-\n"));
  assert_non_null(strstr(out, "--mode\tchoice\t0\t0\t0\tsetpoint\tforce,velocity,setpoint\n"));
  assert_non_null(strstr(out, "--flag\tflag\t"));
  int lines = 0;
  for (const char *p = out; *p; p++) lines += *p == '\n';
  assert_int_equal(lines, 9);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_values),
      cmocka_unit_test(test_custom),
      cmocka_unit_test(test_refusals),
      cmocka_unit_test(test_usage_and_table),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
