/* nd_parse: strict number parsing. strtod/strtol accept trailing junk and silently
 * saturate; these do not. */
#include "nd_parse.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int nd_parse_double(const char *s, const char *what, double lo, double hi, double *out,
                    char *err, int errlen) {
  char *end;
  if (!s || !*s) {
    snprintf(err, errlen, "%s: empty value, expected a number in [%g, %g]", what, lo, hi);
    return -1;
  }
  /* strtod's ERANGE is not the test: an overflow returns HUGE_VAL, refused as not finite;
   * an underflow returns the rounded subnormal or zero, accepted, so a subnormal printed
   * with %.17g parses back. */
  double v = strtod(s, &end);
  if (*end || !isfinite(v)) {
    snprintf(err, errlen, "%s: '%s' is not a finite number", what, s);
    return -1;
  }
  if (v < lo || v > hi) {
    snprintf(err, errlen, "%s: %g is out of range [%g, %g]", what, v, lo, hi);
    return -1;
  }
  *out = v;
  return 0;
}

int nd_parse_int(const char *s, const char *what, long lo, long hi, int *out, char *err,
                 int errlen) {
  char *end;
  if (!s || !*s) {
    snprintf(err, errlen, "%s: empty value, expected an integer in [%ld, %ld]", what, lo, hi);
    return -1;
  }
  errno = 0;
  long v = strtol(s, &end, 10);
  if (*end || errno == ERANGE) {
    snprintf(err, errlen, "%s: '%s' is not an integer", what, s);
    return -1;
  }
  if (v < lo || v > hi) {
    snprintf(err, errlen, "%s: %ld is out of range [%ld, %ld]", what, v, lo, hi);
    return -1;
  }
  *out = (int)v;
  return 0;
}

int nd_parse_u64(const char *s, const char *what, uint64_t *out, char *err, int errlen) {
  char *end;
  if (!s || !*s || *s == '-') {
    snprintf(err, errlen, "%s: '%s' is not a non-negative integer", what, s ? s : "");
    return -1;
  }
  errno = 0;
  unsigned long long v = strtoull(s, &end, 10);
  if (*end || errno == ERANGE) {
    snprintf(err, errlen, "%s: '%s' is not a non-negative integer", what, s);
    return -1;
  }
  *out = (uint64_t)v;
  return 0;
}

int nd_parse_list(const char *s, const char *what, int n, double lo, double hi, double *out,
                  char *err, int errlen) {
  char tok[64];
  const char *p = s ? s : "";
  for (int i = 0; i < n; i++) {
    const char *e = strchr(p, ',');
    size_t len = e ? (size_t)(e - p) : strlen(p);
    if ((e == NULL) != (i == n - 1) || len >= sizeof(tok)) {
      snprintf(err, errlen, "%s: expected %d comma-separated numbers, got '%s'", what, n,
               s ? s : "");
      return -1;
    }
    memcpy(tok, p, len);
    tok[len] = '\0';
    if (nd_parse_double(tok, what, lo, hi, &out[i], err, errlen)) return -1;
    p = e ? e + 1 : p + len;
  }
  return 0;
}

int nd_parse_box(const char *s, const char *what, double lim, nd_box *box, char *err,
                 int errlen) {
  double b[4];
  if (nd_parse_list(s, what, 4, -lim, lim, b, err, errlen)) return -1;
  if (!(b[0] < b[2]) || !(b[1] < b[3])) {
    snprintf(err, errlen, "%s: '%s' is not a box XLO,YLO,XHI,YHI with XLO < XHI and "
             "YLO < YHI", what, s);
    return -1;
  }
  box->lo[0] = b[0], box->lo[1] = b[1], box->hi[0] = b[2], box->hi[1] = b[3];
  return 0;
}
