/* test_goals: the episode runner's goal-list parser (processes/nd_goal.h). */
#include "nd_test.h"

#include <string.h>

#include "nd_goal.h"

static char err[512];

/* Parse a NUL-terminated text into g; returns the parser's code, goal count in *n. */
static int parse(const char *text, nd_goal *g, int cap, int *n) {
  *n = 0;
  err[0] = '\0';
  return nd_goal_list_parse(text, strlen(text), "g.txt", g, cap, n, err, sizeof(err));
}

static void test_valid_file(void **state) {
  (void)state;
  nd_goal g[8];
  int n;
  const char *text =
      "# a goal list\n"
      "\n"
      "0.15 0 0\n"
      "  0.25\t0.10  0.4   # turn a little\r\n"
      "-0.1 -0.2 -1.5 1e-3\n"
      "   \t  \n"
      "0.3 0.3 3.0 0.02 7.5";  /* no final newline */
  assert_int_equal(parse(text, g, 8, &n), 0);
  assert_int_equal(n, 4);
  assert_near(g[0].x, 0.15, 0);
  assert_near(g[0].yaw, 0.0, 0);
  assert_near(g[0].eps, 0.0, 0); /* 0: the runner's default */
  assert_int_equal(g[0].line, 3);
  assert_near(g[1].y, 0.10, 0);
  assert_near(g[1].yaw, 0.4, 0);
  assert_int_equal(g[1].line, 4);
  assert_near(g[2].x, -0.1, 0);
  assert_near(g[2].eps, 1e-3, 0);
  assert_near(g[2].tau, 0.0, 0);
  assert_near(g[3].eps, 0.02, 0);
  assert_near(g[3].tau, 7.5, 0);
  assert_int_equal(g[3].line, 7);
}

static void test_empty_text_has_no_goals(void **state) {
  (void)state;
  nd_goal g[2];
  int n;
  assert_int_equal(parse("", g, 2, &n), 0);
  assert_int_equal(n, 0);
  assert_int_equal(parse("# only a comment\n\n  \n", g, 2, &n), 0);
  assert_int_equal(n, 0);
}

/* Each malformed line is refused with FILE:LINE and a word about what is wrong. */
static void test_errors_name_line_and_cause(void **state) {
  (void)state;
  static const struct {
    const char *text, *where, *what;
  } cases[] = {
      {"0 0 0\n0.1 0.2\n", "g.txt:2:", "2 fields"},
      {"0.1 0.2 0.3 0.01 5 9\n", "g.txt:1:", "6 fields"},
      {"\n\n0.1 zero 0\n", "g.txt:3:", "y"},
      {"0.1 0.2 45\n", "g.txt:1:", "radians"},
      {"0.1 0.2 0 0\n", "g.txt:1:", "eps"},
      {"0.1 0.2 0 1.5\n", "g.txt:1:", "eps"},
      {"0.1 0.2 0 0.01 -1\n", "g.txt:1:", "time_limit"},
      {"0.1 0.2 0 0.01 4000\n", "g.txt:1:", "time_limit"},
      {"11 0 0\n", "g.txt:1:", "x"},
      {"0.1 0.2 nan\n", "g.txt:1:", "yaw"},
      {"0.1 0.2 inf\n", "g.txt:1:", "yaw"},
      {"0.1 0.2 0.3x\n", "g.txt:1:", "yaw"},
      {"0.1,0.2,0.3\n", "g.txt:1:", "1 field"},
      {"0 0 0\n0.1 0.2 \x01\n", "g.txt:2:", "control byte"},
  };
  for (size_t i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
    nd_goal g[4];
    int n;
    assert_int_equal(parse(cases[i].text, g, 4, &n), -1);
    if (strncmp(err, cases[i].where, strlen(cases[i].where)) || !strstr(err, cases[i].what))
      fail_msg("case %zu: message '%s' lacks '%s' or '%s'", i, err, cases[i].where,
               cases[i].what);
  }
}

/* Bytes a text file should not have: a NUL, an overlong line. */
static void test_binary_and_long_lines(void **state) {
  (void)state;
  nd_goal g[4];
  int n = 0;
  const char nul[] = "0 0 0\n0.1\0 0 0\n";
  assert_int_equal(nd_goal_list_parse(nul, sizeof(nul) - 1, "b", g, 4, &n, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "b:2:"));
  assert_non_null(strstr(err, "NUL"));

  static char lng[ND_GOAL_MAX_LINE + 64];
  memset(lng, ' ', sizeof(lng) - 1);
  lng[sizeof(lng) - 1] = '\0';
  memcpy(lng, "0 0 0 #", 7);
  assert_int_equal(parse(lng, g, 4, &n), -1);
  assert_non_null(strstr(err, "longer"));
}

/* The buffer is read only within len: a goal beyond len does not exist. */
static void test_respects_length(void **state) {
  (void)state;
  nd_goal g[4];
  int n = 0;
  const char *text = "0.1 0 0\n0.2 0 0\n";
  assert_int_equal(nd_goal_list_parse(text, 8, "t", g, 4, &n, err, sizeof(err)), 0);
  assert_int_equal(n, 1);
  /* Cut inside the second line: "0.2 0" has two fields. */
  n = 0;
  assert_int_equal(nd_goal_list_parse(text, 13, "t", g, 4, &n, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "t:2:"));
}

/* Appends after what is there; refuses beyond cap. */
static void test_append_and_cap(void **state) {
  (void)state;
  nd_goal g[3];
  int n = 1;
  g[0].x = 42.0;
  const char *text = "0.1 0 0\n0.2 0 0\n0.3 0 0\n";
  assert_int_equal(nd_goal_list_parse(text, strlen(text), "c", g, 3, &n, err, sizeof(err)), -1);
  assert_int_equal(n, 3);
  assert_near(g[0].x, 42.0, 0);
  assert_near(g[1].x, 0.1, 0);
  assert_near(g[2].x, 0.2, 0);
  assert_non_null(strstr(err, "c:3:"));
  assert_non_null(strstr(err, "more than 3"));
}

static void test_command_line_goal(void **state) {
  (void)state;
  nd_goal g;
  assert_int_equal(nd_goal_parse_arg("0.2,-0.05,0.5", &g, err, sizeof(err)), 0);
  assert_near(g.x, 0.2, 0);
  assert_near(g.y, -0.05, 0);
  assert_near(g.yaw, 0.5, 0);
  assert_near(g.eps, 0.0, 0);
  assert_int_equal(g.line, 0);
  assert_int_equal(nd_goal_parse_arg("0.2,0,0,0.001,3", &g, err, sizeof(err)), 0);
  assert_near(g.eps, 1e-3, 0);
  assert_near(g.tau, 3.0, 0);

  const char *bad[] = {"0.2,0", "0.2,,0", "a,b,c", "0.2,0,0,", "0.2 0 0", "", "0.2,0,90",
                       "0,0,0,0.01,5,1"};
  for (size_t i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
    if (nd_goal_parse_arg(bad[i], &g, err, sizeof(err)) != -1)
      fail_msg("'%s' was accepted", bad[i]);
    char quoted[64];
    snprintf(quoted, sizeof(quoted), "'%s'", bad[i]);
    assert_non_null(strstr(err, quoted));
  }
}

static void test_load_missing_file(void **state) {
  (void)state;
  nd_goal g[2];
  int n = 0;
  assert_int_equal(nd_goal_list_load("/nonexistent/goals.txt", g, 2, &n, err, sizeof(err)), -1);
  assert_non_null(strstr(err, "/nonexistent/goals.txt"));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_valid_file),
      cmocka_unit_test(test_empty_text_has_no_goals),
      cmocka_unit_test(test_errors_name_line_and_cause),
      cmocka_unit_test(test_binary_and_long_lines),
      cmocka_unit_test(test_respects_length),
      cmocka_unit_test(test_append_and_cap),
      cmocka_unit_test(test_command_line_goal),
      cmocka_unit_test(test_load_missing_file),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
