/* test_pool: nd_pool hands out every task exactly once, on valid and exclusive worker
 * indices, returns only when all are done, and survives many dispatches. */
#define _GNU_SOURCE
#include "nd_test.h"

#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "nd_pool.h"

#define MAXW 8

/* ---- every slot exactly once ---- */

typedef struct {
  int *slot;
  atomic_int bad_worker;
  int nworkers;
} count_ctx;

static void count_task(void *vctx, int task, int worker) {
  count_ctx *c = (count_ctx *)vctx;
  if (worker < 0 || worker >= c->nworkers) atomic_fetch_add(&c->bad_worker, 1);
  c->slot[task]++;  /* own slot: a second visit would show as 2 */
}

static void check_once(int nworkers, int ntasks) {
  char err[128] = "";
  nd_pool *pool = nd_pool_create(nworkers, err, sizeof err);
  assert_non_null(pool);
  assert_int_equal(nd_pool_size(pool), nworkers);
  count_ctx c;
  c.slot = (int *)calloc((size_t)ntasks, sizeof(int));
  assert_non_null(c.slot);
  atomic_init(&c.bad_worker, 0);
  c.nworkers = nworkers;
  nd_pool_run(pool, ntasks, count_task, &c);
  int wrong = 0;
  for (int i = 0; i < ntasks; i++) wrong += c.slot[i] != 1;
  assert_int_equal(wrong, 0);
  assert_int_equal(atomic_load(&c.bad_worker), 0);
  free(c.slot);
  nd_pool_free(pool);
}

static void test_many_tiny_tasks(void **state) {
  (void)state;
  check_once(2, 100000);
  check_once(4, 100000);
}

static void test_one_worker(void **state) {
  (void)state;
  check_once(1, 1000);
}

static void test_more_tasks_than_workers(void **state) {
  (void)state;
  check_once(3, 7);
  check_once(4, 2);  /* and fewer */
  check_once(2, 1);
}

/* ---- zero tasks ---- */

static void never_task(void *vctx, int task, int worker) {
  (void)task;
  (void)worker;
  (*(int *)vctx)++;
}

static void test_zero_tasks(void **state) {
  (void)state;
  for (int n = 1; n <= 3; n++) {
    nd_pool *pool = nd_pool_create(n, NULL, 0);
    assert_non_null(pool);
    int calls = 0;
    nd_pool_run(pool, 0, never_task, &calls);
    nd_pool_run(pool, -5, never_task, &calls);
    assert_int_equal(calls, 0);
    nd_pool_free(pool);
  }
}

/* ---- reuse ---- */

typedef struct {
  atomic_long sum;
} sum_ctx;

static void sum_task(void *vctx, int task, int worker) {
  (void)worker;
  atomic_fetch_add(&((sum_ctx *)vctx)->sum, task + 1);
}

static void test_reuse_1000_dispatches(void **state) {
  (void)state;
  nd_pool *pool = nd_pool_create(3, NULL, 0);
  assert_non_null(pool);
  sum_ctx c;
  int wrong = 0;
  for (int d = 0; d < 1000; d++) {
    int n = d % 37;  /* includes 0 and counts below and above the worker count */
    atomic_init(&c.sum, 0);
    nd_pool_run(pool, n, sum_task, &c);
    wrong += atomic_load(&c.sum) != (long)n * (n + 1) / 2;
  }
  assert_int_equal(wrong, 0);
  nd_pool_free(pool);
}

/* ---- worker index exclusive, in range, tied to one thread, 0 = caller ---- */

typedef struct {
  int nworkers;
  atomic_int busy[MAXW];
  atomic_int overlap;      /* a worker index used by two tasks at once */
  atomic_int out_of_range;
  atomic_int thread_mismatch;
  pthread_t owner[MAXW];
  atomic_int owner_set[MAXW];  /* 0 unset, 1 being set, 2 set */
  pthread_t caller;
  atomic_int caller_mismatch;
} excl_ctx;

static void excl_task(void *vctx, int task, int worker) {
  excl_ctx *c = (excl_ctx *)vctx;
  if (worker < 0 || worker >= c->nworkers) {
    atomic_fetch_add(&c->out_of_range, 1);
    return;
  }
  if (atomic_exchange(&c->busy[worker], 1) != 0) atomic_fetch_add(&c->overlap, 1);

  pthread_t self = pthread_self();
  int expect = 0;
  if (atomic_compare_exchange_strong(&c->owner_set[worker], &expect, 1)) {
    c->owner[worker] = self;
    atomic_store(&c->owner_set[worker], 2);
  } else {
    while (atomic_load(&c->owner_set[worker]) != 2) sched_yield();
    if (!pthread_equal(c->owner[worker], self)) atomic_fetch_add(&c->thread_mismatch, 1);
  }
  if (worker == 0 && !pthread_equal(self, c->caller)) atomic_fetch_add(&c->caller_mismatch, 1);

  /* some work so that tasks really overlap in time */
  volatile double x = task;
  for (int i = 0; i < 200; i++) x = x * 1.0000001 + 1.0;
  if (task % 64 == 0) sched_yield();

  atomic_store(&c->busy[worker], 0);
}

static void test_worker_index_exclusive(void **state) {
  (void)state;
  for (int n = 1; n <= 4; n++) {
    nd_pool *pool = nd_pool_create(n, NULL, 0);
    assert_non_null(pool);
    excl_ctx c;
    memset(&c, 0, sizeof c);
    c.nworkers = n;
    c.caller = pthread_self();
    for (int d = 0; d < 20; d++) nd_pool_run(pool, 5000, excl_task, &c);
    assert_int_equal(atomic_load(&c.out_of_range), 0);
    assert_int_equal(atomic_load(&c.overlap), 0);
    assert_int_equal(atomic_load(&c.thread_mismatch), 0);
    assert_int_equal(atomic_load(&c.caller_mismatch), 0);
    nd_pool_free(pool);
  }
}

/* ---- all workers take part: n tasks that each wait for the others ---- */

typedef struct {
  int n;
  atomic_int arrived;
  atomic_int gave_up;
  atomic_int seen[MAXW];
} barrier_ctx;

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void barrier_task(void *vctx, int task, int worker) {
  (void)task;
  barrier_ctx *c = (barrier_ctx *)vctx;
  atomic_fetch_add(&c->seen[worker], 1);
  atomic_fetch_add(&c->arrived, 1);
  /* only completes if all n tasks run at the same time, i.e. on n distinct workers;
   * the deadline turns a broken pool into a failure instead of a hang */
  double t0 = now_s();
  while (atomic_load(&c->arrived) < c->n) {
    if (now_s() - t0 > 10.0) {
      atomic_fetch_add(&c->gave_up, 1);
      return;
    }
    sched_yield();
  }
}

static void test_all_workers_take_part(void **state) {
  (void)state;
  const int n = 3;
  nd_pool *pool = nd_pool_create(n, NULL, 0);
  assert_non_null(pool);
  for (int d = 0; d < 5; d++) {
    barrier_ctx c;
    memset(&c, 0, sizeof c);
    c.n = n;
    nd_pool_run(pool, n, barrier_task, &c);
    assert_int_equal(atomic_load(&c.gave_up), 0);
    for (int w = 0; w < n; w++) assert_int_equal(atomic_load(&c.seen[w]), 1);
  }
  nd_pool_free(pool);
}

static void test_invalid_size(void **state) {
  (void)state;
  char err[128] = "";
  assert_null(nd_pool_create(0, err, sizeof err));
  assert_non_null(strstr(err, "nworkers"));
  nd_pool_free(NULL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_many_tiny_tasks),
      cmocka_unit_test(test_one_worker),
      cmocka_unit_test(test_more_tasks_than_workers),
      cmocka_unit_test(test_zero_tasks),
      cmocka_unit_test(test_reuse_1000_dispatches),
      cmocka_unit_test(test_worker_index_exclusive),
      cmocka_unit_test(test_all_workers_take_part),
      cmocka_unit_test(test_invalid_size),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
