/* The parameter history's re-encoding invariant, shared by fuzz_msgs (entries as bytes)
 * and fuzz_rbuf (entries in a file). */
#ifndef ND_FUZZ_HISTORY_H
#define ND_FUZZ_HISTORY_H

#include <string.h>

#include "fuzz.h"
#include "nd_history.h"

/* e, decoded from the len bytes d, encodes back to d. A version-1 entry comes back as
 * version 2: its fields unchanged at their version-2 offsets (nd_history.h), the box's
 * entries as built, held. what names the caller in a broken invariant. */
static void fz_history_reencodes(const uint8_t *d, size_t len, const nd_history_entry *e,
                                 const char *what) {
  uint8_t out[ND_HISTORY_ENC_SIZE];
  char why[256];
  FZ_CHECK(nd_history_encode(e, out, why, sizeof why) == 0, "%s: %s", what, why);
  if (len != ND_HISTORY_ENC_SIZE_V1) {
    FZ_CHECK(len == sizeof out && memcmp(out, d, len) == 0, "%s: re-encodes differently",
             what);
    return;
  }
  FZ_CHECK(d[0] == 1 && out[0] == 2 && memcmp(out + 4, d + 4, 60) == 0 &&
           memcmp(out + 88, d + 64, 32) == 0 && memcmp(out + 144, d + 96, 24) == 0,
           "%s: version 1 re-encodes differently", what);
  const double zero = 0.0;
  for (int i = ND_NTHETA_PAPER; i < ND_NTHETA; i++)
    FZ_CHECK(!memcmp(&e->mean[i], &nd_theta_true[i], 8) && !memcmp(&e->std[i], &zero, 8),
             "%s: version 1 decoded theta[%d] other than as built and held", what, i);
}

#endif
