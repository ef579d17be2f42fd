/* Process test of the adaptation loop: `nudge-up run` (bridge, executor, planner,
 * adapter) on a replay buffer, nudge-tasks recording one task at a time into it.
 *
 *   netns-run test_proc_adapter BUILD_DIR/bin
 *
 * 1. One task in the running system appends exactly one more valid rollout to the buffer,
 *    and a PARAMS message with the next version, fitted on that many rollouts, arrives.
 *    The adapter runs with the robust ranking (--robust 1e-9), and its log's start line
 *    says so.
 * 2. A SIGKILLed and restarted adapter goes on from its history: it republishes the
 *    version it had reached (>= 2, so a refit from scratch, version 1, cannot pass for
 *    it) without refitting, and the next task gives the version after.
 *    The supervisor restarts the killed adapter (its backoff), as it would in use.
 * 3. `nudge-adapter --offline` with the options nudge-up gave the adapter refits the
 *    recorded buffer once per rollout: versions 1 and 2, made before the kill, come out
 *    with the very thetas the live adapter logged, and its last lines give the last theta.
 *    With --score too, or on a buffer that is not there, it refuses, naming the input.
 *
 * Runs under tests/netns-run, which provides the private namespaces and LCM_DEFAULT_URL
 * (and reports 77, skipped, where namespaces cannot be made). Ends by itself: every wait
 * has a deadline, and the supervisor is stopped with SIGINT (SIGKILL after 20 s).
 * Deadlines and the task's time limit scale with NUDGE_SLOW, and a sanitizer report in
 * any log of the run fails the test, as in every process test (tests/process-lib.sh). */
#define _GNU_SOURCE
#include "nd_test.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <lcm/lcm.h>

#include "nd_parse.h"
#include "nd_rbuf.h"
#include "nudge/nudge_params_t.h"
#include "nudge/nudge_status_t.h"

extern char **environ;

/* Straight pushes along x; eps 1e-3 (~3 cm) so each task is a real push of the object;
 * tau 2 s, times NUDGE_SLOW (tests/process-lib.sh). */
#define EPS "1e-3"
#define TAU_S 2.0

/* A deliberately wrong initial theta, as the loop is meant to start. */
#define THETA "0.6,0.005,0.0001,1"

enum { P_BRIDGE, P_EXECUTOR, P_PLANNER, P_ADAPTER, NPROC };
static const char *names[NPROC] = {"bridge", "executor", "planner", "adapter"};

typedef struct {
  char bin[512], dir[256], buffer[320];
  pid_t up;                   /* nudge-up */
  lcm_t *lcm;
  nudge_params_t_subscription_t *sub_params;
  nudge_status_t_subscription_t *sub_status;
  /* newest PARAMS */
  int have_params;
  int64_t version;
  int32_t buffer_size;
  int64_t params_seen;
  /* newest heartbeat per process */
  pid_t hb_pid[NPROC];
  /* rollouts of the last buffer_count, freed by the next one or teardown, so that a
   * failed assertion does not leak them */
  nd_rollout *rs;
  int nrs;
  double slow;  /* NUDGE_SLOW: deadlines and time limits are multiplied by it */
} world;

static world W;

static double mono(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void on_params(const lcm_recv_buf_t *rb, const char *ch, const nudge_params_t *m,
                      void *user) {
  (void)rb;
  (void)ch;
  (void)user;
  W.have_params = 1;
  W.version = m->version;
  W.buffer_size = m->buffer_size;
  W.params_seen++;
}

static void on_status(const lcm_recv_buf_t *rb, const char *ch, const nudge_status_t *m,
                      void *user) {
  (void)rb;
  (void)ch;
  (void)user;
  for (int i = 0; i < NPROC; i++) {
    char want[64];
    snprintf(want, sizeof(want), "nudge-%s", names[i]);
    if (!strcmp(m->name, want)) W.hb_pid[i] = m->pid;
  }
}

/* Handle LCM for s seconds. */
static void pump(double s) {
  const double end = mono() + s;
  for (double now = mono(); now < end; now = mono()) {
    int ms = (int)(1e3 * (end - now)) + 1;
    lcm_handle_timeout(W.lcm, ms > 100 ? 100 : ms);
  }
}

/* Start nudge-<name> with args (NULL-terminated), output appended to <dir>/<name>.out. */
static pid_t spawn(const char *name, const char *const *args) {
  char path[640], log[320];
  snprintf(path, sizeof(path), "%s/nudge-%s", W.bin, name);
  snprintf(log, sizeof(log), "%s/%s.out", W.dir, name);
  const char *argv[32] = {path};
  for (int i = 0; args[i] && i < 30; i++) argv[i + 1] = args[i];
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, log, O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  pid_t pid = -1;
  int rc = posix_spawn(&pid, path, &fa, NULL, (char *const *)argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc) {
    fprintf(stderr, "cannot start %s: %s\n", path, strerror(rc));
    return -1;
  }
  return pid;
}

/* Wait up to s seconds for a heartbeat of process i from a pid other than not (0: any). */
static int wait_heartbeat(int i, pid_t not, double s) {
  const double end = mono() + s;
  while (mono() < end) {
    if (W.hb_pid[i] > 0 && W.hb_pid[i] != not) return 1;
    pump(0.1);
  }
  return 0;
}

/* Run one task toward goal "x,y,yaw" with recording; return nudge-tasks' exit status. */
static int run_task(const char *goal) {
  char tau[32], wait[32];
  snprintf(tau, sizeof tau, "%g", TAU_S * W.slow);
  snprintf(wait, sizeof wait, "%g", 5.0 * W.slow);
  const char *args[] = {"--record", W.buffer, "--goal", goal, "--eps", EPS, "--tau", tau,
                        "--wait", wait, "--settle", "0", NULL};
  pid_t pid = spawn("tasks", args);
  if (pid < 0) return -1;
  /* Keep handling LCM so PARAMS published meanwhile are seen. */
  int st = 0;
  for (;;) {
    pid_t r = waitpid(pid, &st, WNOHANG);
    if (r == pid) break;
    pump(0.1);
  }
  return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

static void free_rollouts(void) {
  nd_rbuf_free_all(W.rs, W.nrs);
  W.rs = NULL;
  W.nrs = 0;
}

/* Rollouts in the buffer (in W.rs); all must decode (nd_rbuf_read_all refuses
 * otherwise). */
static int buffer_count(void) {
  char err[512];
  nd_rfile_tail tail;
  struct stat st;
  free_rollouts();
  if (stat(W.buffer, &st) != 0) return 0;
  if (nd_rbuf_read_all(W.buffer, &W.rs, &W.nrs, &tail, err, sizeof(err)))
    fail_msg("%s", err);
  assert_int_equal(tail.status, ND_RFILE_END);
  return W.nrs;
}

/* Wait up to s seconds for PARAMS with version v; return 1 when seen. */
static int wait_version(int64_t v, double s) {
  const double end = mono() + s;
  while (mono() < end) {
    if (W.have_params && W.version == v) return 1;
    pump(0.1);
  }
  return 0;
}

static void one_task_one_record_one_version(void **state) {
  (void)state;
  const int n0 = buffer_count();
  const int64_t v0 = W.have_params ? W.version : 0;

  assert_int_equal(run_task("0.15,0,0"), 0);
  const int n1 = buffer_count();
  assert_int_equal(n1, n0 + 1);
  const nd_rollout *r = &W.rs[n1 - 1];
  /* A task of at most tau at 1 kHz (it may end early on success). */
  assert_true(r->n >= 50 && r->n <= (int)(1000 * TAU_S * W.slow) + 100);
  assert_near(r->dt, 0.001, 0.0);
  assert_int_equal(r->control, ND_CTRL_FORCE);
  assert_true(r->outcome == ND_OUTCOME_SUCCESS || r->outcome == ND_OUTCOME_TIMEOUT);
  assert_near(r->goal[0], 0.15, 1e-12);
  /* The sphere was pushed toward the goal and the setpoints went with it. */
  assert_true(r->ee[2 * (r->n - 1)] - r->ee_pos[0] > 0.02);
  assert_true(r->sp[6 * (r->n - 1)] - r->ee_pos[0] > 0.02);
  const double *last = nd_rollout_obj(r, r->n - 1);
  assert_true(last[0] - r->obj_pos[0] > 0.005);
  /* The object's full pose from MOCAP: on the table (half height 2.5 cm, it may hop a
   * millimetre), a unit quaternion at every step. */
  for (int k = 0; k < r->n; k++) {
    const double *o = nd_rollout_obj(r, k);
    assert_near(o[2], 0.025, 0.002);
    assert_near(o[3] * o[3] + o[4] * o[4] + o[5] * o[5] + o[6] * o[6], 1, 1e-9);
  }
  free_rollouts();

  if (!wait_version(v0 + 1, 60.0 * W.slow))
    fail_msg("no PARAMS version %lld within 60 s (newest: %lld)", (long long)(v0 + 1),
             (long long)W.version);
  assert_int_equal(W.buffer_size, n1);

  /* The fit ran as configured: the adapter's start line in its log says so. */
  char path[400], line[2048];
  snprintf(path, sizeof(path), "%s/run/adapter.log", W.dir);
  FILE *f = fopen(path, "r");
  assert_non_null(f);
  int said = 0;
  while (fgets(line, sizeof(line), f))
    said |= strstr(line, "ranked by the robust score of scale 1e-09 m^2,") != NULL;
  fclose(f);
  assert_true(said);
}

static void killed_adapter_resumes(void **state) {
  (void)state;
  /* Two fits at least before the kill: an adapter that ignored its history would refit
   * the buffer as version 1, which must not pass for a resumed version. */
  if (!W.have_params) one_task_one_record_one_version(state);
  assert_int_equal(run_task("0.28,0,0"), 0);
  const int n0 = buffer_count();
  const int64_t v = W.version + 1;
  assert_true(v >= 2);
  if (!wait_version(v, 60.0 * W.slow))
    fail_msg("no PARAMS version %lld within 60 s (newest: %lld)", (long long)v,
             (long long)W.version);
  assert_int_equal(W.buffer_size, n0);
  pump(1.5); /* idle: no refit pending */
  assert_int_equal(W.version, v);

  /* The adapter the supervisor started: the pid of its heartbeats. */
  const pid_t old = W.hb_pid[P_ADAPTER];
  assert_true(old > 0);
  assert_int_equal(kill(old, SIGKILL), 0);
  pump(0.05);
  W.have_params = 0;
  W.version = -1;
  W.params_seen = 0;
  /* The supervisor notices within 0.2 s and restarts it after its first backoff, 0.2 s. */
  if (!wait_heartbeat(P_ADAPTER, old, 15.0 * W.slow))
    fail_msg("no heartbeat of a restarted nudge-adapter within 15 s (see %s/run)", W.dir);
  /* It republishes the version it reached, and does not refit a covered buffer. */
  pump(2.5 * W.slow);
  assert_true(W.params_seen >= 2);
  assert_int_equal(W.version, v);

  assert_int_equal(W.buffer_size, n0);

  /* The next task's refit continues the numbering. */
  assert_int_equal(run_task("0.40,0,0"), 0);
  const int n = buffer_count();
  if (!wait_version(v + 1, 60.0 * W.slow))
    fail_msg("no PARAMS version %lld within 60 s after the restart (newest: %lld)",
             (long long)(v + 1), (long long)W.version);
  assert_int_equal(W.buffer_size, n);
}

/* Run a shell command line; its exit status (-1 if it did not run or was killed). */
static int shell(const char *cmd) {
  const int st = system(cmd);
  return st != -1 && WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* The text after "theta " on the line of refit version v in file path, up to ", std";
 * 1 when found. */
static int refit_theta(const char *path, int v, char *theta, int len) {
  char want[48], line[2048];
  snprintf(want, sizeof(want), "refit version %d: ", v);
  FILE *f = fopen(path, "r");
  if (!f) return 0;
  int found = 0;
  while (!found && fgets(line, sizeof(line), f)) {
    const char *p = strstr(line, want), *t = p ? strstr(p, ", theta ") : NULL;
    const char *e = t ? strstr(t, ", std ") : NULL;
    if (!e) continue;
    snprintf(theta, len, "%.*s", (int)(e - t - 8), t + 8);
    found = 1;
  }
  fclose(f);
  return found;
}

static void offline_repeats_the_live_refits(void **state) {
  if (W.version < 3) killed_adapter_resumes(state);
  const int n = buffer_count();
  free_rollouts();
  assert_true(n >= 3);
  char cmd[2400], out[400], live[400];
  snprintf(live, sizeof(live), "%s/run/adapter.log", W.dir);
  snprintf(out, sizeof(out), "%s/offline.out", W.dir);
  /* The options nudge-up started the adapter with: the first line of its log. */
  snprintf(cmd, sizeof(cmd),
           "'%s/nudge-adapter' $(sed -n '1s/.*: starting nudge-adapter //p' '%s') --offline "
           ">'%s' 2>'%s/offline.err'", W.bin, live, out, W.dir);
  assert_int_equal(shell(cmd), 0);
  for (int v = 1; v <= 2; v++) {
    char a[256], b[256];
    assert_true(refit_theta(live, v, a, sizeof(a)));
    assert_true(refit_theta(out, v, b, sizeof(b)));
    assert_string_equal(b, a);
  }
  /* One refit per rollout, the last on all of them, and its theta as name value unit
   * lines: the slide entry as printed on the line, to its 6 digits. */
  char last[256], beyond[256], want[64];
  assert_true(refit_theta(out, n, last, sizeof(last)));
  assert_false(refit_theta(out, n + 1, beyond, sizeof(beyond)));
  snprintf(cmd, sizeof(cmd),
           "grep -q '^refit version %d: %d rollout(s) in' '%s' && grep -qx 'refits %d count' '%s'",
           n, n, out, n, out);
  assert_int_equal(shell(cmd), 0);
  snprintf(want, sizeof(want), "%.6g", strtod(last, NULL));
  snprintf(cmd, sizeof(cmd),
           "awk '$1 == \"theta_slide\" && $3 == \"1\" { printf \"%%.6g\", $2 }' '%s' | "
           "grep -qx '%s'", out, want);
  assert_int_equal(shell(cmd), 0);

  /* Refusals name what is wrong: the exit status, then the message. */
  char err[400];
  snprintf(err, sizeof(err), "%s/refused.err", W.dir);
  snprintf(cmd, sizeof(cmd),
           "'%s/nudge-adapter' --buffer '%s' --offline --score 1,0.005,0.0001,1 2>'%s'", W.bin,
           W.buffer, err);
  assert_int_equal(shell(cmd), 2);
  snprintf(cmd, sizeof(cmd), "grep -q -- '--offline and --score' '%s'", err);
  assert_int_equal(shell(cmd), 0);
  snprintf(cmd, sizeof(cmd), "'%s/nudge-adapter' --buffer '%s/none.nrb' --offline 2>'%s'",
           W.bin, W.dir, err);
  assert_int_equal(shell(cmd), 1);
  snprintf(cmd, sizeof(cmd), "grep -q 'none.nrb' '%s'", err);
  assert_int_equal(shell(cmd), 0);
}

/* SIGINT to the supervisor (it stops the processes in order); SIGKILL after 20 s (times
 * NUDGE_SLOW).
 * Return its exit status. */
static int stop_up(void) {
  if (W.up <= 0) return -1;
  kill(W.up, SIGINT);
  const double end = mono() + 20.0 * W.slow;
  int st = 0;
  while (waitpid(W.up, &st, WNOHANG) == 0) {
    if (mono() > end) {
      fprintf(stderr, "nudge-up did not stop within %g s of SIGINT: SIGKILL\n", 20.0 * W.slow);
      kill(W.up, SIGKILL);
      waitpid(W.up, &st, 0);
      break;
    }
    usleep(20000);
  }
  W.up = 0;
  return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

static int setup(void **state) {
  (void)state;
  const char *url = getenv("LCM_DEFAULT_URL");
  if (!url) {
    fprintf(stderr, "test_proc_adapter: run me under tests/netns-run\n");
    return -1;
  }
  snprintf(W.dir, sizeof(W.dir), "/tmp/nd_proc_adapter_XXXXXX");
  if (!mkdtemp(W.dir)) return -1;
  snprintf(W.buffer, sizeof(W.buffer), "%s/replay.nrb", W.dir);
  W.lcm = lcm_create(url);
  if (!W.lcm) {
    fprintf(stderr, "lcm_create(%s) failed: no multicast route?\n", url);
    return -1;
  }
  W.sub_params = nudge_params_t_subscribe(W.lcm, "PARAMS", on_params, NULL);
  W.sub_status = nudge_status_t_subscribe(W.lcm, "STATUS", on_status, NULL);

  char logdir[320];
  snprintf(logdir, sizeof(logdir), "%s/run", W.dir);
  /* The adapter ranks by the robust score: the default (L) runs in test_up_signals and
   * test_soak, so both reach a real process. */
  const char *args[] = {"run", "--log-dir", logdir, "--buffer", W.buffer, "--theta", THETA,
                        "--planner-arg", "--threads", "--planner-arg", "1",
                        "--adapter-arg", "--threads", "--adapter-arg", "1",
                        "--adapter-arg", "--robust", "--adapter-arg", "1e-9", NULL};
  W.up = spawn("up", args);
  for (int i = 0; i < NPROC; i++)
    if (W.up < 0 || !wait_heartbeat(i, 0, 30.0 * W.slow)) {
      fprintf(stderr, "nudge-%s did not come up (see %s)\n", names[i], logdir);
      stop_up();
      return -1;
    }
  return 0;
}

/* Sanitizer reports in the logs of the run: the one check of tests/process-lib.sh, which
 * prints what it found. Return 0 if there is none. */
static int sanitizer_scan(void) {
  char cmd[900];
  snprintf(cmd, sizeof cmd, "bash -c '. \"$0\" && pt_sanitizer_scan \"$1\"' '%s' '%s'",
           ND_PROCESS_LIB, W.dir);
  const int st = system(cmd);
  if (st == 0) return 0;
  if (st == -1 || !WIFEXITED(st) || WEXITSTATUS(st) != 1)
    fprintf(stderr, "test_proc_adapter: could not scan %s for sanitizer reports\n", W.dir);
  return -1;
}

static int teardown(void **state) {
  (void)state;
  int rc = stop_up();
  free_rollouts();
  if (W.lcm) {
    nudge_params_t_unsubscribe(W.lcm, W.sub_params);
    nudge_status_t_unsubscribe(W.lcm, W.sub_status);
    lcm_destroy(W.lcm);
  }
  /* Every process has exited now, so every leak report has been written. */
  if (sanitizer_scan() != 0 && rc == 0) rc = 1;
  char cmd[400];
  if (rc != 0 || getenv("ND_KEEP")) {
    fprintf(stderr, "nudge-up exited with %d; logs kept in %s\n", rc, W.dir);
  } else {
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", W.dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", W.dir);
  }
  return rc == 0 ? 0 : -1;
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: netns-run test_proc_adapter BIN_DIR\n");
    return 2;
  }
  snprintf(W.bin, sizeof(W.bin), "%s", argv[1]);
  char err[256];
  const char *slow = getenv("NUDGE_SLOW");
  int k = 1;
  if (slow && nd_parse_int(slow, "NUDGE_SLOW", 1, 99, &k, err, sizeof err)) {
    fprintf(stderr, "test_proc_adapter: %s\n", err);
    return 2;
  }
  W.slow = k;
  signal(SIGPIPE, SIG_IGN);
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(one_task_one_record_one_version),
      cmocka_unit_test(killed_adapter_resumes),
      cmocka_unit_test(offline_repeats_the_live_refits),
  };
  return cmocka_run_group_tests(tests, setup, teardown);
}
