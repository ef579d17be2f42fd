/* nd_parse: strict parsing of numbers from command lines and text files.
 * The whole string must be the number; range is checked; the message names `what`. */
#ifndef ND_PARSE_H
#define ND_PARSE_H

#include <stdint.h>

/* Parse a finite double in [lo, hi]. Return 0, or -1 with a message. */
int nd_parse_double(const char *s, const char *what, double lo, double hi, double *out,
                    char *err, int errlen);

/* Parse a decimal integer in [lo, hi]. Return 0, or -1 with a message. */
int nd_parse_int(const char *s, const char *what, long lo, long hi, int *out, char *err,
                 int errlen);

/* Parse exactly n comma-separated finite doubles, each in [lo, hi], into out.
 * Return 0, or -1 with a message naming what. */
int nd_parse_list(const char *s, const char *what, int n, double lo, double hi, double *out,
                  char *err, int errlen);

/* An axis-aligned box in the table plane, m. */
typedef struct {
  double lo[2], hi[2];
} nd_box;

/* Parse "XLO,YLO,XHI,YHI": four finite numbers within [-lim, lim] with XLO < XHI and
 * YLO < YHI. Return 0, or -1 with a message naming what. */
int nd_parse_box(const char *s, const char *what, double lim, nd_box *box, char *err,
                 int errlen);

/* Parse an unsigned 64-bit decimal integer. Return 0, or -1 with a message. */
int nd_parse_u64(const char *s, const char *what, uint64_t *out, char *err, int errlen);

#endif
