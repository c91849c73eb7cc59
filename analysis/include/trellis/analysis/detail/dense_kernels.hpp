// dense_kernels.hpp (private) — the dense products of the Riccati solve, with an AVX2+FMA path.
//
// Why: the Lyapunov (Bartels–Stewart) solve of every Newton iteration is dominated by four
// nx×nx×nx products (the congruences ZᵀXZ and ZYZᵀ), and the right-hand side by a few more. The
// library is built for the baseline x86-64 (SSE2), where Eigen's product kernel retires about
// 1.5 flops per instruction; with AVX2 and FMA four products-and-sums fit in one instruction.
// The product below runs a 8×4 register-blocked FMA kernel when the CPU has AVX2 and FMA
// (checked once at run time; the kernel is compiled for those instructions alone, with no Eigen
// or other shared inline code in it) and Eigen's product otherwise: same results up to rounding.
// Matrices are column-major; the nx of the Riccati solve fit in L2, so no packing is done.
#pragma once

#include <Eigen/Core>

// Loop annotation: the iterations are independent (an output may be an input at the same index,
// never a shifted overlap), so the loop vectorizes without run-time overlap checks.
#if defined(__clang__)
#define TRELLIS_IVDEP _Pragma("clang loop vectorize(assume_safety)")
#else
#define TRELLIS_IVDEP _Pragma("GCC ivdep")
#endif

namespace trellis::detail {

/// C (m×n, leading dimension ldc) = alpha · A · op(B), or C += alpha · A · op(B) (accumulate);
/// A m×k column-major (lda), op(B) = B (k×n, ldb) or Bᵀ (B n×k, ldb). upperOnly (not with
/// accumulate): only C(i, j) with i ≤ j is required (entries below the diagonal may be written
/// or not). C must not alias A or B.
void matmul(Eigen::Index m, Eigen::Index n, Eigen::Index k, double alpha, const double* A,
            Eigen::Index lda, const double* B, Eigen::Index ldb, bool transB, double* C,
            Eigen::Index ldc, bool upperOnly, bool accumulate = false);

/// Σ x_i y_i over n entries (AVX2+FMA when available, like matmul).
double dotProduct(const double* x, const double* y, Eigen::Index n);

/// Every one of the n entries finite (one pass, no branch per entry).
bool finiteEntries(const double* x, Eigen::Index n);

/// In place: the upper-triangular U with UᵀU = A for symmetric A (n×n, lda; the upper triangle
/// is read and overwritten, the strict lower one left alone; work: n doubles). False, as soon as
/// it happens, if a pivot is not positive (or not finite): A is not positive definite (to
/// working precision).
bool choleskyUpper(double* A, Eigen::Index n, Eigen::Index lda, double* work);

/// Which kernel matmul (and dotProduct) uses: the AVX2+FMA one (true) when the CPU has it, else Eigen's.
bool matmulUsesAvx2();
/// Tests only: force Eigen's product (true) or restore the automatic choice (false).
void matmulForceGeneric(bool force);

}  // namespace trellis::detail
