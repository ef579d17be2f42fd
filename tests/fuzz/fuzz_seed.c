/* Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/<target>/) with the real
 * encoders, so that the seeds follow the formats when they change:
 *   fuzz-seed DIR   (DIR is usually tests/fuzz/corpus)
 * Seeds are small valid inputs the fuzzer mutates from: a replay buffer with two short
 * rollouts (whole and with a torn tail), a parameter history, a raw rollout encoding, one
 * message of each LCM type, a history entry in each encoding version, and goal files. */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "nd_rbuf.h"
#include "nd_history.h"
#include "ndp_validate.h"

static const char *root;

static void die(const char *what) {
  fprintf(stderr, "fuzz-seed: %s\n", what);
  exit(1);
}

static void path_of(char *p, size_t cap, const char *target, const char *name) {
  snprintf(p, cap, "%s/%s", root, target);
  if (mkdir(p, 0755) && errno != EEXIST) die(strerror(errno));
  snprintf(p, cap, "%s/%s/%s", root, target, name);
}

static void put(const char *target, const char *name, const void *d, size_t n) {
  char p[4096];
  path_of(p, sizeof p, target, name);
  FILE *f = fopen(p, "wb");
  if (!f || fwrite(d, 1, n, f) != n || fclose(f)) die(p);
}

/* A short pushing rollout: the sphere approaches and pushes the box along x. */
static void rollout(nd_rollout *r, int n, int64_t task) {
  memset(r, 0, sizeof *r);
  if (nd_rollout_alloc(r, n)) die("alloc");
  r->task_id = task;
  r->utime = 1795496793000000 + task;
  r->outcome = task % 2 ? ND_OUTCOME_SUCCESS : ND_OUTCOME_TIMEOUT;
  r->control = ND_CTRL_FORCE;
  r->dt = 1e-3;
  const double goal[3] = {0.1, 0.05, 0.3}, theta[4] = {1.0, 0.005, 1e-4, 0.1};
  memcpy(r->goal, goal, sizeof goal);
  memcpy(r->theta, theta, sizeof theta);
  r->obj_pos[2] = 0.025;
  r->obj_quat[0] = 1.0;
  r->ee_pos[0] = -0.08;
  for (int i = 0; i < n; i++) {
    r->u[2 * i] = 0.5;
    double *o = nd_rollout_obj(r, i); /* along x, turning slowly */
    o[0] = 1e-4 * i;
    o[2] = 0.025;
    o[3] = cos(1e-4 * i);
    o[6] = sin(1e-4 * i);
    r->ee[2 * i] = -0.08 + 1e-3 * i;
    r->sp[6 * i] = -0.08 + 1e-3 * (i + 1);
    r->sp[6 * i + 2] = 1.0;
  }
}

static void seed_rbuf(void) {
  char p[4096], err[512];
  nd_rfile_writer w;
  nd_rollout r;
  /* Two rollouts, then the same file with a third cut short. */
  path_of(p, sizeof p, "fuzz_rbuf", "two_rollouts.buf");
  unlink(p);
  if (nd_rbuf_open(&w, p, NULL, err, sizeof err)) die(err);
  for (int k = 1; k <= 2; k++) {
    rollout(&r, 2 + k, k);
    if (nd_rbuf_append(&w, &r, err, sizeof err)) die(err);
    if (k == 1) {
      unsigned char enc[ND_ROLLOUT_ENC_FIXED + 3 * ND_ROLLOUT_ENC_STEP];
      size_t len;
      if (nd_rollout_encode(&r, enc, sizeof enc, &len, err, sizeof err)) die(err);
      put("fuzz_rbuf", "rollout.bin", enc, len);
    }
    nd_rollout_free(&r);
  }
  const int64_t whole = w.end;
  rollout(&r, 2, 3);
  if (nd_rbuf_append(&w, &r, err, sizeof err)) die(err);
  nd_rollout_free(&r);
  nd_rfile_writer_close(&w);
  char q[4096];
  path_of(q, sizeof q, "fuzz_rbuf", "torn_tail.buf");
  if (truncate(p, (off_t)(whole + 100)) || rename(p, q)) die(strerror(errno));
  if (nd_rbuf_open(&w, p, NULL, err, sizeof err)) die(err);  /* two_rollouts.buf again */
  for (int k = 1; k <= 2; k++) {
    rollout(&r, 2 + k, k);
    if (nd_rbuf_append(&w, &r, err, sizeof err)) die(err);
    nd_rollout_free(&r);
  }
  nd_rfile_writer_close(&w);

  /* A parameter history of three refits: begun in version 1 (the paper's four fitted, the
   * box as built), continued in version 2 with the box fitted too. */
  path_of(p, sizeof p, "fuzz_rbuf", "history.buf");
  unlink(p);
  if (nd_rfile_open_append(&w, p, ND_RFILE_KIND_PARAMS, NULL, err, sizeof err)) die(err);
  for (int v = 1; v <= 3; v++) {
    nd_history_entry e = {.version = v, .utime = 1795496794000000 + v,
                           .buffer_created = 1795496793000000, .mask = 7,
                           .mean = {0.8, 0.004, 1e-4, 0.1, 1.0, 0.0, 0.0},
                           .std = {0.05, 1e-3, 2e-5, 0},
                           .loss = 0.01 / v, .fit_time = 2.5, .buffer_size = v};
    if (v > 1) {
      const double box[3] = {1.1, 0.008, -0.004}, box_std[3] = {0.05, 1.5e-3, 2.5e-3};
      e.mask = 0x77;  /* all but the sphere mass */
      memcpy(e.mean + ND_TH_BOX_SCALE, box, sizeof box);
      memcpy(e.std + ND_TH_BOX_SCALE, box_std, sizeof box_std);
    }
    unsigned char b[ND_HISTORY_ENC_SIZE], b1[ND_HISTORY_ENC_SIZE_V1];
    if (nd_history_encode(&e, b, err, sizeof err)) die(err);
    const void *rec = b;
    size_t n = sizeof b;
    if (v == 1) {  /* version 2's bytes without theta[4..6] (nd_history.h) */
      memcpy(b1, b, 64);
      b1[0] = 1;
      memcpy(b1 + 64, b + 88, 32);
      memcpy(b1 + 96, b + 144, 24);
      rec = b1;
      n = sizeof b1;
      put("fuzz_msgs", "history_entry_v1.bin", b1, sizeof b1);
    }
    if (v == 2) put("fuzz_msgs", "history_entry.bin", b, sizeof b);
    if (nd_rfile_append(&w, ND_RFILE_KIND_PARAMS, rec, n, err, sizeof err)) die(err);
  }
  nd_rfile_writer_close(&w);

  put("fuzz_rbuf", "empty.buf", "", 0);  /* a file created by touch: the writer adopts it */

  /* Damage, then a valid record more than one 64 KiB search window further on: the writer
   * must still see it and refuse. It starts at the first candidate of the second window
   * (nd_rfile.c's nd_rf_find_valid), where a window seam would lose it. */
  {
    enum { WIN = 65536, AT = ND_RFILE_HEADER + 1 + WIN - ND_RFILE_FRAME + 1 };
    static unsigned char f[AT + ND_RFILE_FRAME + 8];
    path_of(p, sizeof p, "fuzz_rbuf", "two_rollouts.buf");
    FILE *in = fopen(p, "rb");
    if (!in || fread(f, 1, ND_RFILE_HEADER, in) != ND_RFILE_HEADER) die(p);
    fclose(in);
    /* zeros from offset 40: a record of kind 0 (corrupt), then nothing plausible */
    unsigned char *r = f + AT;
    r[0] = 8;                             /* len 8 */
    r[4] = ND_RFILE_KIND_ROLLOUTS;        /* kind */
    memcpy(r + 12, "8 bytes.", 8);
    const uLong c = crc32(crc32(0L, r, 8), r + 12, 8);
    for (int i = 0; i < 4; i++) r[8 + i] = (unsigned char)(c >> (8 * i));
    put("fuzz_rbuf", "far_valid.buf", f, sizeof f);
  }
}

#define SEED_MSG(T, m)                                                     \
  do {                                                                     \
    unsigned char b[4096];                                                 \
    const int n = nudge_##T##_encode(b, 0, sizeof b, &m);                  \
    if (n < 0) die("encode " #T);                                          \
    put("fuzz_msgs", #T ".bin", b, (size_t)n);                             \
  } while (0)

static void seed_msgs(void) {
  const int64_t t = 1795496793000000;
  nudge_mocap_t mo = {.utime = t, .seq = 7, .obj_pos = {0.1, 0.0, 0.025},
                      .obj_quat = {1, 0, 0, 0}, .ee_pos = {-0.05, 0, 0.02}};
  SEED_MSG(mocap_t, mo);
  nudge_robot_state_t rs = {.utime = t, .seq = 8, .ee_pos = {-0.05, 0, 0.02},
                            .ee_vel = {0.1, 0, 0}, .ee_force = {2, 0, 0}, .mode = 0};
  SEED_MSG(robot_state_t, rs);
  nudge_ee_cmd_t ec = {.utime = t, .seq = 9, .plan_id = 3, .plan_utime = t - 500,
                       .mode = 0, .p = {-0.05, 0, 0.02}, .v = {0.1, 0, 0}, .a = {0.5, 0, 0},
                       .seg_end_utime = t + 200000, .seg_key = {0.0, 0.0, 0.2, 0.0},
                       .brake_utime = t + 200000, .rest_utime = t + 300000,
                       .hold = {0.02, 0.0}};
  SEED_MSG(ee_cmd_t, ec);
  nudge_plan_t pl = {.utime = t, .plan_id = 3, .task_id = 1, .state_utime = t - 1000,
                     .M = 2, .keypoints = {{0.0, 0.01, 0.2, 0.0}, {0.05, 0.02, 0.1, 0.0}},
                     .T = 0.3, .cost = 0.02, .task_error = 0.01, .iterations = 4,
                     .evals = 512, .plan_ms = 40, .theta_version = 1,
                     .predicted = {0.12, 0.01, 0.05}};
  SEED_MSG(plan_t, pl);
  nudge_task_t tk = {.utime = t, .task_id = 1, .goal_x = 0.1, .goal_y = 0.05,
                     .goal_yaw = 0.3, .eps = 0.01, .time_limit = 5, .v_max = 0.3};
  SEED_MSG(task_t, tk);
  nudge_params_t pa = {.utime = t, .version = 2, .theta_mean = {0.8, 0.004, 1e-4, 0.1, 1.1, 0.008, -0.004},
                       .theta_std = {0.05, 1e-3, 2e-5, 0, 0.1, 0.002, 0.002}, .fit_mask = 0x77, .loss = 0.01,
                       .buffer_size = 2};
  SEED_MSG(params_t, pa);
  nudge_episode_t ep = {.utime = t, .task_id = 1, .event = 1, .reason = "goal reached",
                        .time = 2.5, .task_error = 0.004};
  SEED_MSG(episode_t, ep);
  nudge_status_t st = {.utime = t, .name = "nudge-executor", .pid = 4242,
                       .state = "running", .received = 1000, .published = 990,
                       .rejected = 1, .period_p50_us = 50, .period_p99_us = 900,
                       .period_max_us = 4000, .overruns = 3, .uptime = 12.5};
  SEED_MSG(status_t, st);
  nudge_arm_state_t ar = {.utime = t, .seq = 3, .q = {0, -0.3, 0, -2.2, 0, 1.9, 0.8},
                          .dq = {0.1, 0, 0, 0, 0, 0, 0}, .tau = {0, 10, 0, -5, 0, 1, 0}};
  SEED_MSG(arm_state_t, ar);
  nudge_place_t pc = {.utime = t, .place_id = 5, .x = 0.0, .y = 0.0, .yaw = 0.0, .clear = 0.01,
                      .park = 1, .park_x = -0.1, .park_y = 0.0};
  SEED_MSG(place_t, pc);
}

static void seed_goals(void) {
  static const char goals[] =
      "# x y yaw [eps [time_limit]]: m, m, rad, -, s\n"
      "0.10 0.05 0.3\n"
      "\n"
      "-0.1\t0.0  -1.5708 0.02   # tab and spaces\n"
      "0 0.1 3.14159 1e-2 5.0\r\n"
      "  0.05 -0.05 0\n";
  put("fuzz_goals", "goals.txt", goals, sizeof goals - 1);
  static const char one[] = "0.1,0.05,0.3,0.01,5";  /* the --goal form */
  put("fuzz_goals", "goal_arg.txt", one, sizeof one - 1);
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: fuzz-seed DIR\n  writes the seed corpora into DIR/<target>/\n");
    return 2;
  }
  root = argv[1];
  if (mkdir(root, 0755) && errno != EEXIST) die(strerror(errno));
  seed_rbuf();
  seed_msgs();
  seed_goals();
  return 0;
}
