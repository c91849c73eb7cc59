// Tests for control/src/nvector_kernels.hpp (private): every replaced N_Vector operation against
// SUNDIALS's own serial implementation on the same data.
#include "trellis/analysis/detail/dense_kernels.hpp"
#include "nvector_kernels.hpp"
#include "sundials_raii.hpp"

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <cmath>

using trellis::detail::Vector;

namespace {

struct Pair {  // the same vector twice: SUNDIALS's serial operations and the kernels
  Pair(SUNContext ctx, const Eigen::VectorXd& v) : ref(N_VNew_Serial(v.size(), ctx)),
                                                   fast(N_VNew_Serial(v.size(), ctx)) {
    trellis::detail::useKernels(fast.get());
    set(v);
  }
  void set(const Eigen::VectorXd& v) {
    Eigen::Map<Eigen::VectorXd>(NV_DATA_S(ref.get()), v.size()) = v;
    Eigen::Map<Eigen::VectorXd>(NV_DATA_S(fast.get()), v.size()) = v;
  }
  double diff() const {
    const auto n = NV_LENGTH_S(ref.get());
    return (Eigen::Map<const Eigen::VectorXd>(NV_DATA_S(ref.get()), n) -
            Eigen::Map<const Eigen::VectorXd>(NV_DATA_S(fast.get()), n))
        .cwiseAbs()
        .maxCoeff();
  }
  Vector ref, fast;
};

}  // namespace

namespace {

void checkKernels() {
  trellis::detail::Context context(trellis::detail::createContext());
  SUNContext ctx = context.get();
  const int n = 37;
  Eigen::VectorXd a = Eigen::VectorXd::Random(n), b = Eigen::VectorXd::Random(n),
                  w = Eigen::VectorXd::Random(n).cwiseAbs().array() + 0.1;
  Pair x(ctx, a), y(ctx, b), z(ctx, Eigen::VectorXd::Zero(n)), wt(ctx, w),
      mask(ctx, Eigen::VectorXd::Random(n));
  // The operation table is copied by clones (CVODES's work vectors).
  Vector clone(N_VClone(x.fast.get()));
  CHECK(clone.get()->ops->nvlinearsum == x.fast.get()->ops->nvlinearsum);
  CHECK(x.ref.get()->ops->nvlinearsum != x.fast.get()->ops->nvlinearsum);

  auto both = [&](auto&& op) {
    op(x.ref.get(), y.ref.get(), z.ref.get(), wt.ref.get());
    op(x.fast.get(), y.fast.get(), z.fast.get(), wt.fast.get());
  };
  both([](N_Vector u, N_Vector v, N_Vector r, N_Vector) { N_VLinearSum(0.3, u, -1.7, v, r); });
  CHECK(z.diff() < 1e-15);
  both([](N_Vector u, N_Vector v, N_Vector, N_Vector) { N_VLinearSum(2.0, u, 1.0, v, v); });  // aliasing
  CHECK(y.diff() < 1e-15);
  both([](N_Vector u, N_Vector v, N_Vector r, N_Vector) { N_VProd(u, v, r); });
  CHECK(z.diff() < 1e-15);
  both([](N_Vector u, N_Vector, N_Vector r, N_Vector w2) { N_VDiv(u, w2, r); });
  CHECK(z.diff() < 1e-13);
  both([](N_Vector u, N_Vector, N_Vector r, N_Vector) { N_VScale(-0.25, u, r); });
  CHECK(z.diff() < 1e-15);
  both([](N_Vector u, N_Vector, N_Vector r, N_Vector) { N_VAbs(u, r); });
  CHECK(z.diff() == 0.0);
  both([](N_Vector, N_Vector, N_Vector r, N_Vector w2) { N_VInv(w2, r); });
  CHECK(z.diff() < 1e-13);
  both([](N_Vector u, N_Vector, N_Vector r, N_Vector) { N_VAddConst(u, 0.5, r); });
  CHECK(z.diff() < 1e-15);
  both([](N_Vector, N_Vector, N_Vector r, N_Vector) { N_VConst(3.5, r); });
  CHECK(z.diff() == 0.0);
  CHECK(N_VDotProd(x.fast.get(), y.fast.get()) ==
        Approx(N_VDotProd(x.ref.get(), y.ref.get())).epsilon(1e-14));
  CHECK(N_VMaxNorm(x.fast.get()) == N_VMaxNorm(x.ref.get()));
  CHECK(N_VWrmsNorm(x.fast.get(), wt.fast.get()) ==
        Approx(N_VWrmsNorm(x.ref.get(), wt.ref.get())).epsilon(1e-14));
  CHECK(N_VWrmsNormMask(x.fast.get(), wt.fast.get(), mask.fast.get()) ==
        Approx(N_VWrmsNormMask(x.ref.get(), wt.ref.get(), mask.ref.get())).epsilon(1e-14));

  // Fused and array operations (z = X_0 in place for the linear combination).
  double c[3] = {0.5, -2.0, 1.25};
  N_Vector Xr[3] = {z.ref.get(), x.ref.get(), y.ref.get()};
  N_Vector Xf[3] = {z.fast.get(), x.fast.get(), y.fast.get()};
  N_VLinearCombination(3, c, Xr, z.ref.get());
  N_VLinearCombination(3, c, Xf, z.fast.get());
  CHECK(z.diff() < 1e-14);
  N_Vector Yr[2] = {y.ref.get(), z.ref.get()}, Yf[2] = {y.fast.get(), z.fast.get()};
  N_VScaleAddMulti(2, c, x.ref.get(), Yr, Yr);
  N_VScaleAddMulti(2, c, x.fast.get(), Yf, Yf);
  CHECK(y.diff() < 1e-14);
  CHECK(z.diff() < 1e-14);
  double dr[2], df[2];
  N_VDotProdMulti(2, x.ref.get(), Yr, dr);
  N_VDotProdMulti(2, x.fast.get(), Yf, df);
  CHECK(df[0] == Approx(dr[0]).epsilon(1e-14));
  CHECK(df[1] == Approx(dr[1]).epsilon(1e-14));
  N_Vector Wr[2] = {wt.ref.get(), wt.ref.get()}, Wf[2] = {wt.fast.get(), wt.fast.get()};
  N_VWrmsNormVectorArray(2, Yr, Wr, dr);
  N_VWrmsNormVectorArray(2, Yf, Wf, df);
  CHECK(df[1] == Approx(dr[1]).epsilon(1e-14));
  N_VLinearSumVectorArray(2, 1.5, Yr, -1.0, Yr, Yr);
  N_VLinearSumVectorArray(2, 1.5, Yf, -1.0, Yf, Yf);
  CHECK(y.diff() < 1e-14);
  N_VScaleVectorArray(2, c, Yr, Yr);
  N_VScaleVectorArray(2, c, Yf, Yf);
  CHECK(z.diff() < 1e-14);
  N_VConstVectorArray(2, -1.0, Yr);
  N_VConstVectorArray(2, -1.0, Yf);
  CHECK(y.diff() == 0.0);

  // Linear combinations of 1…8 vectors (the kernels take three per pass), into a separate
  // vector and in place (z = X_0).
  Pair v0(ctx, Eigen::VectorXd::Random(n)), v1(ctx, Eigen::VectorXd::Random(n)),
      v2(ctx, Eigen::VectorXd::Random(n)), v3(ctx, Eigen::VectorXd::Random(n));
  double cc[8] = {0.7, -1.1, 2.3, 0.4, -0.9, 1.6, -0.2, 1.0};
  for (int nv = 1; nv <= 8; ++nv) {
    for (bool inPlace : {false, true}) {
      N_Vector Vr[8], Vf[8];
      Pair* pool[4] = {&v0, &v1, &v2, &v3};
      for (int i = 0; i < nv; ++i) {
        Vr[i] = pool[i % 4]->ref.get();
        Vf[i] = pool[i % 4]->fast.get();
      }
      if (inPlace) {  // X_0 = z, the others distinct from it
        Vr[0] = z.ref.get();
        Vf[0] = z.fast.get();
      }
      N_VLinearCombination(nv, cc, Vr, z.ref.get());
      N_VLinearCombination(nv, cc, Vf, z.fast.get());
      INFO("nv = " << nv << ", in place = " << inPlace);
      CHECK(z.diff() < 1e-14);  // the same sums in the same order (FMA on the AVX2 path)
    }
  }
}

}  // namespace

TEST_CASE("nvector kernels equal SUNDIALS's serial operations") {
  INFO("AVX2 kernels in use: " << trellis::detail::matmulUsesAvx2());
  checkKernels();
}

TEST_CASE("nvector kernels equal SUNDIALS's serial operations on the generic path") {
  trellis::detail::matmulForceGeneric(true);
  checkKernels();
  trellis::detail::matmulForceGeneric(false);
}
