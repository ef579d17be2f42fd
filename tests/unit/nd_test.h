/* nd_test: what every cmocka test of the project includes. cmocka needs these system
 * headers first and has no floating-point assertion, so assert_near lives here. */
#ifndef ND_TEST_H
#define ND_TEST_H

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <cmocka.h>

/* Fail unless |a - b| <= tol (and both are finite), printing both values. */
#define assert_near(a, b, tol)                                                       \
  do {                                                                               \
    double nd_a_ = (a), nd_b_ = (b), nd_t_ = (tol);                                  \
    if (!(isfinite(nd_a_) && isfinite(nd_b_) && fabs(nd_a_ - nd_b_) <= nd_t_))      \
      fail_msg("%s = %.17g, %s = %.17g, differ by more than %g", #a, nd_a_, #b,    \
               nd_b_, nd_t_);                                                        \
  } while (0)

#endif
