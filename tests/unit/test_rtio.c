/* nd_rtio: the mailbox never hands out a torn value, the ring keeps order and counts drops,
 * both under a real concurrent writer thread. */
#include "nd_test.h"

#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "nd_rtio.h"

#define N_POSTS 200000
#define WORDS 64  /* 512-byte payloads: many words to tear */

/* Reads the reader has completed, for the writer's pacing. */
static atomic_ulong mailbox_reads;

static void *mailbox_writer(void *arg) {
  nd_mailbox *mb = arg;
  uint64_t buf[WORDS];
  unsigned long seen = 0;
  for (uint64_t i = 1; i <= N_POSTS; i++) {
    for (int w = 0; w < WORDS; w++) buf[w] = i * 1000003u + (uint64_t)w;
    nd_mailbox_post(mb, buf, sizeof(buf));
    /* Leave gaps between posts, like a real I/O thread, so that some reads race a write;
     * and every 256 posts wait for the reader to complete one, so that it gets hundreds of
     * reads in however the scheduler of a loaded machine places the two threads. */
    if (i % 16 == 0) sched_yield();
    if (i % 256 == 0) {
      while (atomic_load(&mailbox_reads) == seen) sched_yield();
      seen = atomic_load(&mailbox_reads);
    }
  }
  return NULL;
}

static void test_mailbox_no_torn_reads(void **state) {
  (void)state;
  nd_mailbox *mb = malloc(sizeof(*mb));
  nd_mailbox_init(mb);
  uint64_t version = 0, buf[WORDS];
  assert_int_equal(nd_mailbox_take(mb, &version, buf, sizeof(buf)), 0);
  pthread_t th;
  pthread_create(&th, NULL, mailbox_writer, mb);
  uint64_t last = 0, reads = 0;
  atomic_store(&mailbox_reads, 0);
  while (last < N_POSTS) {
    int n = nd_mailbox_take(mb, &version, buf, sizeof(buf));
    if (n == 0) {
      sched_yield();
      continue;
    }
    assert_int_equal(n, sizeof(buf));
    uint64_t i = (buf[0]) / 1000003u;
    for (int w = 0; w < WORDS; w++) assert_true(buf[w] == i * 1000003u + (uint64_t)w);
    assert_true(i > last);  /* each take is newer than the previous one */
    last = i;
    reads++;
    atomic_store(&mailbox_reads, reads);
  }
  pthread_join(th, NULL);
  printf("mailbox: %llu consistent reads of %d posts\n", (unsigned long long)reads, N_POSTS);
  assert_true(reads >= N_POSTS / 256);  /* the pacing's guarantee */
  /* Nothing new after the last read; a too-small buffer is refused. */
  assert_int_equal(nd_mailbox_take(mb, &version, buf, sizeof(buf)), 0);
  uint64_t v0 = 0;
  assert_int_equal(nd_mailbox_take(mb, &v0, buf, 8), -1);
  assert_int_equal(nd_mailbox_post(mb, buf, ND_RTIO_MAX + 1), -1);
  free(mb);
}

static void *ring_producer(void *arg) {
  nd_ring *r = arg;
  for (uint64_t i = 0; i < N_POSTS; i++) {
    unsigned char *p;
    while (!(p = nd_ring_reserve(r))) {
    }
    memcpy(p, &i, sizeof(i));
    nd_ring_commit(r, (int)(i % 7), sizeof(i));
  }
  return NULL;
}

static void test_ring_order(void **state) {
  (void)state;
  nd_ring *r = malloc(sizeof(*r));
  nd_ring_init(r);
  pthread_t th;
  pthread_create(&th, NULL, ring_producer, r);
  uint64_t next = 0, v;
  int tag;
  while (next < N_POSTS) {
    int n = nd_ring_pop(r, &tag, &v, sizeof(v));
    if (n < 0) continue;
    assert_int_equal(n, sizeof(v));
    assert_true(v == next);
    assert_int_equal(tag, (int)(next % 7));
    next++;
  }
  pthread_join(th, NULL);
  assert_int_equal(nd_ring_pop(r, &tag, &v, sizeof(v)), -1);
  /* The producer spun on a full ring: every refusal was counted as a drop. */
  printf("ring: %d messages in order, %llu refused while full\n", N_POSTS,
         (unsigned long long)atomic_load(&r->dropped));
  free(r);
}

static void test_ring_full(void **state) {
  (void)state;
  nd_ring *r = malloc(sizeof(*r));
  nd_ring_init(r);
  for (int i = 0; i < ND_RING_SLOTS; i++) {
    unsigned char *p = nd_ring_reserve(r);
    assert_non_null(p);
    p[0] = (unsigned char)i;
    nd_ring_commit(r, i, 1);
  }
  assert_null(nd_ring_reserve(r));
  assert_int_equal(atomic_load(&r->dropped), 1);
  unsigned char b[4];
  int tag;
  assert_int_equal(nd_ring_pop(r, &tag, b, sizeof(b)), 1);
  assert_int_equal(tag, 0);
  assert_non_null(nd_ring_reserve(r));
  free(r);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_mailbox_no_torn_reads),
      cmocka_unit_test(test_ring_order),
      cmocka_unit_test(test_ring_full),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
