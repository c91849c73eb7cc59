// nvector_kernels.cpp — Eigen versions of the hot SUNDIALS serial vector operations (see the
// header). Semantics follow the N_Vector specification of SUNDIALS 6 (operation by operation).
#include "nvector_kernels.hpp"

#include "trellis/analysis/detail/dense_kernels.hpp"

#include <Eigen/Core>

#include <cmath>

namespace trellis::detail {

namespace {

using Vec = Eigen::Map<Eigen::ArrayXd>;

Vec arr(N_Vector v) { return Vec(NV_DATA_S(v), NV_LENGTH_S(v)); }

// The streaming operations CVODES calls most (linear sums, scalings, linear combinations) as
// plain loops, compiled twice: for the baseline and, chosen at run time like matmul (see
// dense_kernels.hpp), for AVX2. The loops are the same source (always inlined into both); the
// AVX2 build may contract a·x + y to one FMA (a rounding-level difference). TRELLIS_IVDEP: the
// specification allows z to be one of the inputs (the same index, never a shifted overlap).
#define TRELLIS_INLINE inline __attribute__((always_inline))
#define TRELLIS_AVX2 __attribute__((target("avx2,fma")))
using Index = sunindextype;

// z = a x + b y (z may be x or y).
TRELLIS_INLINE void linearSumLoop(double a, const double* x, double b, const double* y, double* z,
                                  Index n) {
TRELLIS_IVDEP
  for (Index i = 0; i < n; ++i) z[i] = a * x[i] + b * y[i];
}
// z = c x (z may be x).
TRELLIS_INLINE void scaleLoop(double c, const double* x, double* z, Index n) {
TRELLIS_IVDEP
  for (Index i = 0; i < n; ++i) z[i] = c * x[i];
}
// z = Σ c_i X_i (z may be X_0, no other), three vectors per pass over z; the sum is formed in the
// order c_0 X_0 + c_1 X_1 + … like one vector at a time.
TRELLIS_INLINE void linearCombinationLoop(int nv, const double* c, N_Vector* X, double* z,
                                          Index n) {
  int k;
  if (nv >= 3) {
    const double *x0 = NV_DATA_S(X[0]), *x1 = NV_DATA_S(X[1]), *x2 = NV_DATA_S(X[2]);
    const double c0 = c[0], c1 = c[1], c2 = c[2];
TRELLIS_IVDEP
    for (Index i = 0; i < n; ++i) z[i] = c0 * x0[i] + c1 * x1[i] + c2 * x2[i];
    k = 3;
  } else if (nv == 2) {
    const double *x0 = NV_DATA_S(X[0]), *x1 = NV_DATA_S(X[1]);
    const double c0 = c[0], c1 = c[1];
TRELLIS_IVDEP
    for (Index i = 0; i < n; ++i) z[i] = c0 * x0[i] + c1 * x1[i];
    return;
  } else {
    scaleLoop(c[0], NV_DATA_S(X[0]), z, n);
    return;
  }
  for (; k + 3 <= nv; k += 3) {
    const double *x0 = NV_DATA_S(X[k]), *x1 = NV_DATA_S(X[k + 1]), *x2 = NV_DATA_S(X[k + 2]);
    const double c0 = c[k], c1 = c[k + 1], c2 = c[k + 2];
TRELLIS_IVDEP
    for (Index i = 0; i < n; ++i) z[i] = ((z[i] + c0 * x0[i]) + c1 * x1[i]) + c2 * x2[i];
  }
  for (; k < nv; ++k) {
    const double* x0 = NV_DATA_S(X[k]);
    const double c0 = c[k];
TRELLIS_IVDEP
    for (Index i = 0; i < n; ++i) z[i] = z[i] + c0 * x0[i];
  }
}
// Z_i = c_i x + Y_i.
TRELLIS_INLINE void scaleAddLoop(double c, const double* x, const double* y, double* z, Index n) {
TRELLIS_IVDEP
  for (Index i = 0; i < n; ++i) z[i] = c * x[i] + y[i];
}

TRELLIS_AVX2 void linearSumAvx2(double a, const double* x, double b, const double* y, double* z,
                                Index n) {
  linearSumLoop(a, x, b, y, z, n);
}
TRELLIS_AVX2 void scaleAvx2(double c, const double* x, double* z, Index n) { scaleLoop(c, x, z, n); }
TRELLIS_AVX2 void linearCombinationAvx2(int nv, const double* c, N_Vector* X, double* z,
                                        Index n) {
  linearCombinationLoop(nv, c, X, z, n);
}
TRELLIS_AVX2 void scaleAddAvx2(double c, const double* x, const double* y, double* z, Index n) {
  scaleAddLoop(c, x, y, z, n);
}

void linearSum(realtype a, N_Vector x, realtype b, N_Vector y, N_Vector z) {
  const Index n = NV_LENGTH_S(z);
  if (matmulUsesAvx2()) {
    linearSumAvx2(a, NV_DATA_S(x), b, NV_DATA_S(y), NV_DATA_S(z), n);
  } else {
    linearSumLoop(a, NV_DATA_S(x), b, NV_DATA_S(y), NV_DATA_S(z), n);
  }
}
void constant(realtype c, N_Vector z) { arr(z).setConstant(c); }
void prod(N_Vector x, N_Vector y, N_Vector z) { arr(z) = arr(x) * arr(y); }
void div(N_Vector x, N_Vector y, N_Vector z) { arr(z) = arr(x) / arr(y); }
void scale(realtype c, N_Vector x, N_Vector z) {
  const Index n = NV_LENGTH_S(z);
  if (matmulUsesAvx2()) {
    scaleAvx2(c, NV_DATA_S(x), NV_DATA_S(z), n);
  } else {
    scaleLoop(c, NV_DATA_S(x), NV_DATA_S(z), n);
  }
}
void absolute(N_Vector x, N_Vector z) { arr(z) = arr(x).abs(); }
void inv(N_Vector x, N_Vector z) { arr(z) = arr(x).inverse(); }
void addConst(N_Vector x, realtype b, N_Vector z) { arr(z) = arr(x) + b; }
realtype dotProd(N_Vector x, N_Vector y) { return (arr(x) * arr(y)).sum(); }
realtype maxNorm(N_Vector x) {
  return NV_LENGTH_S(x) == 0 ? 0.0 : arr(x).abs().maxCoeff();
}
realtype wSqrSum(N_Vector x, N_Vector w) { return (arr(x) * arr(w)).square().sum(); }
realtype wrmsNorm(N_Vector x, N_Vector w) {
  return std::sqrt(wSqrSum(x, w) / static_cast<realtype>(NV_LENGTH_S(x)));
}
realtype wrmsNormMask(N_Vector x, N_Vector w, N_Vector id) {
  const realtype s = ((arr(id) > 0.0).cast<double>() * (arr(x) * arr(w)).square()).sum();
  return std::sqrt(s / static_cast<realtype>(NV_LENGTH_S(x)));
}

// z = Σ c_i X_i (z may be X_0, no other).
int linearCombination(int nv, realtype* c, N_Vector* X, N_Vector z) {
  if (nv < 1) return -1;
  if (nv == 1 && X[0] == z && c[0] == 1.0) return 0;
  if (matmulUsesAvx2()) {
    linearCombinationAvx2(nv, c, X, NV_DATA_S(z), NV_LENGTH_S(z));
  } else {
    linearCombinationLoop(nv, c, X, NV_DATA_S(z), NV_LENGTH_S(z));
  }
  return 0;
}
// Z_i = c_i x + Y_i (Z_i may be Y_i).
int scaleAddMulti(int nv, realtype* c, N_Vector x, N_Vector* Y, N_Vector* Z) {
  if (nv < 1) return -1;
  const Index n = NV_LENGTH_S(x);
  for (int i = 0; i < nv; ++i) {
    if (matmulUsesAvx2()) {
      scaleAddAvx2(c[i], NV_DATA_S(x), NV_DATA_S(Y[i]), NV_DATA_S(Z[i]), n);
    } else {
      scaleAddLoop(c[i], NV_DATA_S(x), NV_DATA_S(Y[i]), NV_DATA_S(Z[i]), n);
    }
  }
  return 0;
}
int dotProdMulti(int nv, N_Vector x, N_Vector* Y, realtype* d) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) d[i] = dotProd(x, Y[i]);
  return 0;
}
int linearSumArray(int nv, realtype a, N_Vector* X, realtype b, N_Vector* Y, N_Vector* Z) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) linearSum(a, X[i], b, Y[i], Z[i]);
  return 0;
}
int scaleArray(int nv, realtype* c, N_Vector* X, N_Vector* Z) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) scale(c[i], X[i], Z[i]);
  return 0;
}
int constArray(int nv, realtype c, N_Vector* Z) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) constant(c, Z[i]);
  return 0;
}
int wrmsNormArray(int nv, N_Vector* X, N_Vector* W, realtype* nrm) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) nrm[i] = wrmsNorm(X[i], W[i]);
  return 0;
}

}  // namespace

void useKernels(N_Vector v) {
  N_Vector_Ops ops = v->ops;
  ops->nvlinearsum = linearSum;
  ops->nvconst = constant;
  ops->nvprod = prod;
  ops->nvdiv = div;
  ops->nvscale = scale;
  ops->nvabs = absolute;
  ops->nvinv = inv;
  ops->nvaddconst = addConst;
  ops->nvdotprod = dotProd;
  ops->nvmaxnorm = maxNorm;
  ops->nvwrmsnorm = wrmsNorm;
  ops->nvwrmsnormmask = wrmsNormMask;
  ops->nvdotprodlocal = dotProd;
  ops->nvmaxnormlocal = maxNorm;
  ops->nvwsqrsumlocal = wSqrSum;
  ops->nvlinearcombination = linearCombination;
  ops->nvscaleaddmulti = scaleAddMulti;
  ops->nvdotprodmulti = dotProdMulti;
  ops->nvlinearsumvectorarray = linearSumArray;
  ops->nvscalevectorarray = scaleArray;
  ops->nvconstvectorarray = constArray;
  ops->nvwrmsnormvectorarray = wrmsNormArray;
}

}  // namespace trellis::detail
