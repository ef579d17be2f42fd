/* nd_pool: fixed pthread pool with a blocking parallel-for.
 *
 * One dispatch = one generation. The caller publishes (fn, ctx, ntasks) under the mutex,
 * bumps the generation and wakes the workers; every worker (the caller included) then
 * pulls task indices from one atomic counter until it runs dry, and the caller waits
 * until every thread has reported back. Because the caller waits for all threads, no
 * thread can miss or repeat a generation, and nothing is allocated per dispatch. */
#include "nd_pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  nd_pool *pool;
  int index;  /* worker index, >= 1 (the caller is 0) */
} nd_pool_worker;

struct nd_pool {
  int nworkers;
  int nthreads;                 /* threads actually started (nworkers - 1 when healthy) */
  pthread_t *threads;
  nd_pool_worker *workers;

  pthread_mutex_t mutex;
  pthread_cond_t wake;          /* generation changed or quit */
  pthread_cond_t done;          /* pending reached 0 */
  unsigned long generation;
  int pending;                  /* threads that have not finished the current generation */
  int quit;

  /* the current dispatch; written under the mutex before the generation is bumped */
  nd_pool_fn fn;
  void *ctx;
  int ntasks;
  atomic_int next;              /* next task index to hand out */
};

static void nd_pool_err(char *err, int errlen, const char *msg) {
  if (err && errlen > 0) snprintf(err, (size_t)errlen, "%s", msg);
}

/* Pull tasks until none are left. fn/ctx/ntasks are stable for the whole generation. */
static void nd_pool_drain(nd_pool *pool, int worker) {
  for (;;) {
    int task = atomic_fetch_add_explicit(&pool->next, 1, memory_order_relaxed);
    /* unsigned: a counter wrapped past INT_MAX must not yield a negative task */
    if ((unsigned)task >= (unsigned)pool->ntasks) return;
    pool->fn(pool->ctx, task, worker);
  }
}

static void *nd_pool_main(void *arg) {
  nd_pool_worker *w = (nd_pool_worker *)arg;
  nd_pool *pool = w->pool;
  unsigned long seen = 0;

  pthread_mutex_lock(&pool->mutex);
  for (;;) {
    while (!pool->quit && pool->generation == seen) pthread_cond_wait(&pool->wake, &pool->mutex);
    if (pool->quit) break;
    seen = pool->generation;
    pthread_mutex_unlock(&pool->mutex);

    nd_pool_drain(pool, w->index);

    /* the mutex also publishes this thread's task results to the caller */
    pthread_mutex_lock(&pool->mutex);
    if (--pool->pending == 0) pthread_cond_signal(&pool->done);
  }
  pthread_mutex_unlock(&pool->mutex);
  return NULL;
}

/* Stop and join the threads started so far. */
static void nd_pool_stop(nd_pool *pool) {
  pthread_mutex_lock(&pool->mutex);
  pool->quit = 1;
  pthread_cond_broadcast(&pool->wake);
  pthread_mutex_unlock(&pool->mutex);
  for (int i = 0; i < pool->nthreads; i++) pthread_join(pool->threads[i], NULL);
  pool->nthreads = 0;
}

nd_pool *nd_pool_create(int nworkers, char *err, int errlen) {
  if (nworkers < 1) {
    nd_pool_err(err, errlen, "nd_pool: nworkers must be >= 1");
    return NULL;
  }
  nd_pool *pool = (nd_pool *)calloc(1, sizeof(nd_pool));
  if (!pool) {
    nd_pool_err(err, errlen, "nd_pool: out of memory");
    return NULL;
  }
  pool->nworkers = nworkers;
  atomic_init(&pool->next, 0);
  if (nworkers == 1) return pool;  /* everything runs on the caller */

  pool->threads = (pthread_t *)calloc((size_t)(nworkers - 1), sizeof(pthread_t));
  pool->workers = (nd_pool_worker *)calloc((size_t)(nworkers - 1), sizeof(nd_pool_worker));
  if (!pool->threads || !pool->workers) {
    free(pool->threads);
    free(pool->workers);
    free(pool);
    nd_pool_err(err, errlen, "nd_pool: out of memory");
    return NULL;
  }
  pthread_mutex_init(&pool->mutex, NULL);
  pthread_cond_init(&pool->wake, NULL);
  pthread_cond_init(&pool->done, NULL);

  for (int i = 0; i < nworkers - 1; i++) {
    pool->workers[i].pool = pool;
    pool->workers[i].index = i + 1;
    int rc = pthread_create(&pool->threads[i], NULL, nd_pool_main, &pool->workers[i]);
    if (rc != 0) {
      if (err && errlen > 0)
        snprintf(err, (size_t)errlen, "nd_pool: pthread_create failed for worker %d: %s", i + 1,
                 strerror(rc));
      nd_pool_free(pool);
      return NULL;
    }
    pool->nthreads++;
  }
  return pool;
}

int nd_pool_size(const nd_pool *pool) {
  return pool->nworkers;
}

void nd_pool_run(nd_pool *pool, int ntasks, nd_pool_fn fn, void *ctx) {
  if (ntasks <= 0) return;
  if (pool->nworkers == 1) {
    for (int t = 0; t < ntasks; t++) fn(ctx, t, 0);
    return;
  }

  pthread_mutex_lock(&pool->mutex);
  pool->fn = fn;
  pool->ctx = ctx;
  pool->ntasks = ntasks;
  atomic_store_explicit(&pool->next, 0, memory_order_relaxed);
  pool->pending = pool->nthreads;
  pool->generation++;
  pthread_cond_broadcast(&pool->wake);
  pthread_mutex_unlock(&pool->mutex);

  nd_pool_drain(pool, 0);

  pthread_mutex_lock(&pool->mutex);
  while (pool->pending > 0) pthread_cond_wait(&pool->done, &pool->mutex);
  pthread_mutex_unlock(&pool->mutex);
}

void nd_pool_free(nd_pool *pool) {
  if (!pool) return;
  if (pool->nworkers > 1) {
    nd_pool_stop(pool);
    pthread_cond_destroy(&pool->done);
    pthread_cond_destroy(&pool->wake);
    pthread_mutex_destroy(&pool->mutex);
  }
  free(pool->threads);
  free(pool->workers);
  free(pool);
}
