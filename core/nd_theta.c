/* nd_theta: names, bounds and parsing of theta. */
#include "nd_theta.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "nd_parse.h"

const double nd_theta_true[ND_NTHETA] = {1.0, 0.005, 0.0001, 1.0, 1.0, 0.0, 0.0};
const char *const nd_theta_name[ND_NTHETA] = {
    "sliding friction", "torsional friction", "rolling friction", "sphere mass",
    "box mass scale",   "box COM shift x",    "box COM shift y"};
const char *const nd_theta_key[ND_NTHETA] = {"slide",     "torsion", "roll", "mass",
                                             "box_scale", "com_x",   "com_y"};
const char *const nd_theta_unit[ND_NTHETA] = {"1", "m", "m", "kg", "1", "m", "m"};

int nd_theta_signed(int i) { return i == ND_TH_COM_X || i == ND_TH_COM_Y; }

int nd_theta_check(const double theta[ND_NTHETA], char *err, int errlen) {
  for (int i = 0; i < ND_NTHETA; i++) {
    const double v = theta[i];
    if (nd_theta_signed(i)) {
      if (!(isfinite(v) && fabs(v) <= ND_THETA_COM_MAX)) {
        snprintf(err, errlen, "theta[%d] (%s) = %g: must be finite and within +-%g m", i,
                 nd_theta_name[i], v, ND_THETA_COM_MAX);
        return -1;
      }
      continue;
    }
    const int positive = i == ND_TH_MASS || i == ND_TH_BOX_SCALE;
    if (!isfinite(v) || (positive ? v <= 0 : v < 0) || v > ND_THETA_MAX) {
      snprintf(err, errlen, "theta[%d] (%s) = %g: must be finite, %s and <= %g", i,
               nd_theta_name[i], v, positive ? "> 0" : ">= 0", ND_THETA_MAX);
      return -1;
    }
  }
  return 0;
}

int nd_theta_parse(const char *s, const char *what, double theta[ND_NTHETA], char *err,
                   int errlen) {
  double v[ND_NTHETA];
  memcpy(v, nd_theta_true, sizeof(v));
  int commas = 0;
  for (const char *p = s; *p; p++) commas += *p == ',';
  const int n = commas + 1;
  if (n != ND_NTHETA_PAPER && n != ND_NTHETA) {
    snprintf(err, errlen, "%s: '%.40s': expected %d values (S,T,R,M) or %d (S,T,R,M,B,X,Y)",
             what, s, ND_NTHETA_PAPER, ND_NTHETA);
    return -1;
  }
  if (nd_parse_list(s, what, n, -ND_THETA_MAX, ND_THETA_MAX, v, err, errlen)) return -1;
  /* The list's range admits a zero mass or a negative friction; the message must still
   * name the option. */
  char why[160];
  if (nd_theta_check(v, why, sizeof(why))) {
    snprintf(err, errlen, "%s: %s", what, why);
    return -1;
  }
  memcpy(theta, v, sizeof(v));
  return 0;
}

void nd_theta_str(const double theta[ND_NTHETA], const char *sep, char *buf, int len) {
  int at = 0;
  if (len > 0) buf[0] = '\0';
  for (int i = 0; i < ND_NTHETA && at < len; i++) {
    const int n = snprintf(buf + at, (size_t)(len - at), "%s%.6g", i ? sep : "", theta[i]);
    if (n < 0) break;
    at += n;
  }
}

int nd_theta_parse_mask(const char *s, const char *what, unsigned *mask, char *err,
                        int errlen) {
  unsigned m = 0;
  const char *p = s;
  char keys[96];  /* every short name, for the messages */
  nd_theta_mask_str((1u << ND_NTHETA) - 1, keys, sizeof(keys));
  for (;;) {
    const size_t n = strcspn(p, ",");
    int i = 0;
    while (i < ND_NTHETA && !(strlen(nd_theta_key[i]) == n && !strncmp(p, nd_theta_key[i], n)))
      i++;
    if (n == 0) {
      snprintf(err, errlen, "%s: '%s': no parameter named (%s)", what, s, keys);
      return -1;
    }
    if (i == ND_NTHETA) {
      snprintf(err, errlen, "%s: unknown parameter '%.*s' (%s)", what,
               (int)(n > 40 ? 40 : n), p, keys);
      return -1;
    }
    if (m & (1u << i)) {
      snprintf(err, errlen, "%s: '%s' given twice", what, nd_theta_key[i]);
      return -1;
    }
    m |= 1u << i;
    if (!p[n]) break;
    p += n + 1;
  }
  *mask = m;
  return 0;
}

void nd_theta_mask_str(unsigned mask, char *buf, int len) {
  int at = 0;
  if (len > 0) buf[0] = '\0';
  for (int i = 0; i < ND_NTHETA && at < len; i++)
    if (mask & (1u << i)) {
      const int n = snprintf(buf + at, (size_t)(len - at), "%s%s", at ? "," : "", nd_theta_key[i]);
      if (n < 0) break;
      at += n;
    }
}
