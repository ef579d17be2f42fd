/* nd_rtio: seqlock mailbox and SPSC ring. The payload is copied word by word with
 * relaxed atomics so a reader racing a writer is defined behaviour; the sequence numbers
 * tell it to retry. */
#include "nd_rtio.h"

#include <string.h>

void nd_mailbox_init(nd_mailbox *mb) {
  atomic_store(&mb->seq, 0);
  atomic_store(&mb->len, 0);
  for (int i = 0; i < ND_RTIO_MAX / 8; i++) atomic_store_explicit(&mb->words[i], 0, memory_order_relaxed);
}

int nd_mailbox_post(nd_mailbox *mb, const void *data, int len) {
  if (len < 0 || len > ND_RTIO_MAX) return -1;
  uint64_t s = atomic_load_explicit(&mb->seq, memory_order_relaxed);
  atomic_store_explicit(&mb->seq, s + 1, memory_order_relaxed);
  atomic_thread_fence(memory_order_release);
  const unsigned char *p = data;
  int nw = (len + 7) / 8;
  for (int i = 0; i < nw; i++) {
    uint64_t w = 0;
    int n = len - 8 * i < 8 ? len - 8 * i : 8;
    memcpy(&w, p + 8 * i, n);
    atomic_store_explicit(&mb->words[i], w, memory_order_relaxed);
  }
  atomic_store_explicit(&mb->len, len, memory_order_relaxed);
  atomic_store_explicit(&mb->seq, s + 2, memory_order_release);
  return 0;
}

int nd_mailbox_take(nd_mailbox *mb, uint64_t *version, void *out, int cap) {
  unsigned char *o = out;
  uint64_t s1 = atomic_load_explicit(&mb->seq, memory_order_acquire);
  /* A write in progress may stay in progress for a whole time slice if the writer is
   * preempted: do not spin, report nothing new and let the next cycle take it. */
  if ((s1 & 1) || s1 == *version) return 0;
  int len = atomic_load_explicit(&mb->len, memory_order_relaxed);
  if (len > cap) return -1;
  int nw = (len + 7) / 8;
  for (int i = 0; i < nw; i++) {
    uint64_t w = atomic_load_explicit(&mb->words[i], memory_order_relaxed);
    int n = len - 8 * i < 8 ? len - 8 * i : 8;
    memcpy(o + 8 * i, &w, n);
  }
  atomic_thread_fence(memory_order_acquire);
  if (atomic_load_explicit(&mb->seq, memory_order_relaxed) != s1) return 0;
  *version = s1;
  return len;
}

void nd_ring_init(nd_ring *r) {
  atomic_store(&r->head, 0);
  atomic_store(&r->tail, 0);
  atomic_store(&r->dropped, 0);
}

unsigned char *nd_ring_reserve(nd_ring *r) {
  uint64_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
  uint64_t t = atomic_load_explicit(&r->tail, memory_order_acquire);
  if (h - t >= ND_RING_SLOTS) {
    atomic_fetch_add_explicit(&r->dropped, 1, memory_order_relaxed);
    return NULL;
  }
  return r->slot[h & (ND_RING_SLOTS - 1)].data;
}

void nd_ring_commit(nd_ring *r, int tag, int len) {
  uint64_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
  r->slot[h & (ND_RING_SLOTS - 1)].tag = tag;
  r->slot[h & (ND_RING_SLOTS - 1)].len = len;
  atomic_store_explicit(&r->head, h + 1, memory_order_release);
}

int nd_ring_pop(nd_ring *r, int *tag, void *out, int cap) {
  uint64_t t = atomic_load_explicit(&r->tail, memory_order_relaxed);
  uint64_t h = atomic_load_explicit(&r->head, memory_order_acquire);
  if (t == h) return -1;
  int len = r->slot[t & (ND_RING_SLOTS - 1)].len;
  if (len > cap) len = cap;
  *tag = r->slot[t & (ND_RING_SLOTS - 1)].tag;
  memcpy(out, r->slot[t & (ND_RING_SLOTS - 1)].data, len);
  atomic_store_explicit(&r->tail, t + 1, memory_order_release);
  return len;
}
