/* nd_pool: a fixed-size pthread pool with a blocking parallel-for.
 * Workers are created once; a dispatch allocates nothing. The calling thread takes
 * part as worker 0, so a pool of size 1 runs everything on the caller. */
#ifndef ND_POOL_H
#define ND_POOL_H

typedef struct nd_pool nd_pool;

/* Task body: run task index `task` on worker `worker` in [0, nd_pool_size()). */
typedef void (*nd_pool_fn)(void *ctx, int task, int worker);

/* Create a pool of nworkers >= 1 (nworkers - 1 threads). NULL and a message on error. */
nd_pool *nd_pool_create(int nworkers, char *err, int errlen);

/* Number of workers including the caller. */
int nd_pool_size(const nd_pool *pool);

/* Run fn for every task in [0, ntasks) and return when all are done. Tasks are handed
 * out dynamically; a task's worker index is stable for its duration. Not reentrant. */
void nd_pool_run(nd_pool *pool, int ntasks, nd_pool_fn fn, void *ctx);

/* Stop and join the workers, free the pool. NULL is ignored. */
void nd_pool_free(nd_pool *pool);

#endif
