/* nd_linalg: Cholesky and A A' (nd_linalg.h). */
#include "nd_linalg.h"

#include <math.h>

int nd_chol(double *A, int n) {
  for (int j = 0; j < n; j++) {
    double s = A[j * n + j];
    for (int k = 0; k < j; k++) s -= A[j * n + k] * A[j * n + k];
    if (!(s > 0)) return -1;
    A[j * n + j] = sqrt(s);
    for (int i = j + 1; i < n; i++) {
      double t = A[i * n + j];
      for (int k = 0; k < j; k++) t -= A[i * n + k] * A[j * n + k];
      A[i * n + j] = t / A[j * n + j];
    }
  }
  return 0;
}

void nd_chol_solve(const double *L, int n, const double *b, double *x) {
  for (int i = 0; i < n; i++) {
    double s = b[i];
    for (int k = 0; k < i; k++) s -= L[i * n + k] * x[k];
    x[i] = s / L[i * n + i];
  }
  for (int i = n - 1; i >= 0; i--) {
    double s = x[i];
    for (int k = i + 1; k < n; k++) s -= L[k * n + i] * x[k];
    x[i] = s / L[i * n + i];
  }
}

void nd_aat(const double *A, int r, int c, double lambda, double *out) {
  for (int i = 0; i < r; i++) {
    for (int j = 0; j <= i; j++) {
      double v = 0;
      for (int k = 0; k < c; k++) v += A[i * c + k] * A[j * c + k];
      out[i * r + j] = out[j * r + i] = v;
    }
    out[i * r + i] += lambda;
  }
}
