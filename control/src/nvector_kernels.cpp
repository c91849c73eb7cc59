// nvector_kernels.cpp — Eigen versions of the hot SUNDIALS serial vector operations (see the
// header). Semantics follow the N_Vector specification of SUNDIALS 6 (operation by operation).
#include "nvector_kernels.hpp"

#include <Eigen/Core>

#include <cmath>

namespace trellis::detail {

namespace {

using Vec = Eigen::Map<Eigen::ArrayXd>;

Vec arr(N_Vector v) { return Vec(NV_DATA_S(v), NV_LENGTH_S(v)); }

// z = a x + b y (z may be x or y).
void linearSum(realtype a, N_Vector x, realtype b, N_Vector y, N_Vector z) {
  arr(z) = a * arr(x) + b * arr(y);
}
void constant(realtype c, N_Vector z) { arr(z).setConstant(c); }
void prod(N_Vector x, N_Vector y, N_Vector z) { arr(z) = arr(x) * arr(y); }
void div(N_Vector x, N_Vector y, N_Vector z) { arr(z) = arr(x) / arr(y); }
void scale(realtype c, N_Vector x, N_Vector z) { arr(z) = c * arr(x); }
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
  auto out = arr(z);
  if (X[0] == z) {
    if (c[0] != 1.0) out *= c[0];
  } else {
    out = c[0] * arr(X[0]);
  }
  for (int i = 1; i < nv; ++i) out += c[i] * arr(X[i]);
  return 0;
}
// Z_i = c_i x + Y_i (Z_i may be Y_i).
int scaleAddMulti(int nv, realtype* c, N_Vector x, N_Vector* Y, N_Vector* Z) {
  if (nv < 1) return -1;
  for (int i = 0; i < nv; ++i) arr(Z[i]) = c[i] * arr(x) + arr(Y[i]);
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
