/* nd_rtio: lock-free hand-over between a real-time loop and an I/O thread.
 *
 * A 1 kHz loop must not block on a lock, allocate or do blocking I/O, so it never talks
 * to LCM itself. An I/O thread receives messages and posts the newest of each kind into
 * an nd_mailbox (a single-writer seqlock); the loop reads them without waiting. What the
 * loop publishes goes into an nd_ring (single-producer single-consumer), which the I/O
 * thread drains. Both hold fixed-size byte payloads allocated with the object. */
#ifndef ND_RTIO_H
#define ND_RTIO_H

#include <stdatomic.h>
#include <stdint.h>

#define ND_RTIO_MAX 1024   /* largest payload in bytes */

/* Newest-value mailbox: one writer thread, any number of readers. */
typedef struct {
  _Atomic uint64_t seq;                      /* even: stable; odd: write in progress */
  _Atomic uint64_t words[ND_RTIO_MAX / 8];
  _Atomic int32_t len;
} nd_mailbox;

/* Empty mailbox (version 0). */
void nd_mailbox_init(nd_mailbox *mb);

/* Post len <= ND_RTIO_MAX bytes as the newest value. Return 0, or -1 if too long. */
int nd_mailbox_post(nd_mailbox *mb, const void *data, int len);

/* Copy the newest value into out (cap bytes) if its version differs from *version,
 * updating *version. Return its length, 0 if nothing new (or a write is in progress:
 * it is taken on a later call), -1 if cap is too small. Never waits. */
int nd_mailbox_take(nd_mailbox *mb, uint64_t *version, void *out, int cap);

#define ND_RING_SLOTS 256  /* power of two */

/* Single-producer single-consumer ring of tagged byte messages. */
typedef struct {
  _Atomic uint64_t head;   /* next slot to write, producer-owned */
  _Atomic uint64_t tail;   /* next slot to read, consumer-owned */
  _Atomic uint64_t dropped;/* pushes refused because the ring was full */
  struct {
    int32_t tag, len;
    unsigned char data[ND_RTIO_MAX];
  } slot[ND_RING_SLOTS];
} nd_ring;

void nd_ring_init(nd_ring *r);

/* Reserve the next slot for writing in place (producer). NULL when full (counted as a
 * drop); commit it with nd_ring_commit. */
unsigned char *nd_ring_reserve(nd_ring *r);
void nd_ring_commit(nd_ring *r, int tag, int len);

/* Copy out the oldest message (consumer). Return its length and set *tag, or -1 when empty. */
int nd_ring_pop(nd_ring *r, int *tag, void *out, int cap);

#endif
