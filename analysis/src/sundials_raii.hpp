// sundials_raii.hpp (private) — owners of SUNDIALS objects; destroyed in reverse order of creation.
#pragma once

#include <cvodes/cvodes.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sundials/sundials_linearsolver.h>
#include <sundials/sundials_matrix.h>
#include <sundials/sundials_nonlinearsolver.h>

#include <stdexcept>
#include <string>

namespace trellis::detail {

template <class T, void (*Free)(T)>
class SunHandle {
 public:
  SunHandle() = default;
  explicit SunHandle(T p) : p_(p) {}
  SunHandle(const SunHandle&) = delete;
  SunHandle& operator=(const SunHandle&) = delete;
  ~SunHandle() { if (p_) Free(p_); }
  T get() const { return p_; }
  explicit operator bool() const { return p_ != nullptr; }
  void reset(T p) { if (p_) Free(p_); p_ = p; }

 private:
  T p_ = nullptr;
};

inline void freeContext(SUNContext c) { SUNContext_Free(&c); }
inline void freeVector(N_Vector v) { N_VDestroy(v); }
inline void freeMatrix(SUNMatrix m) { SUNMatDestroy(m); }
inline void freeLinearSolver(SUNLinearSolver s) { SUNLinSolFree(s); }
inline void freeNonlinearSolver(SUNNonlinearSolver s) { SUNNonlinSolFree(s); }
inline void freeCvode(void* mem) { CVodeFree(&mem); }

using Context = SunHandle<SUNContext, freeContext>;
using Vector = SunHandle<N_Vector, freeVector>;
using Matrix = SunHandle<SUNMatrix, freeMatrix>;
using LinearSolver = SunHandle<SUNLinearSolver, freeLinearSolver>;
using NonlinearSolver = SunHandle<SUNNonlinearSolver, freeNonlinearSolver>;
using CvodeMemory = SunHandle<void*, freeCvode>;

/// Members are declared so that destruction runs integrator → solvers → vectors → context.
struct CvodeSession {
  Context context;
  Vector y, dky;
  Matrix jacobian;
  LinearSolver linearSolver;
  NonlinearSolver nonlinearSolver;
  CvodeMemory cvode;
};

inline SUNContext createContext() {
  SUNContext ctx = nullptr;
  if (SUNContext_Create(nullptr, &ctx) != 0 || !ctx) {
    throw std::runtime_error("SUNDIALS: SUNContext_Create failed");
  }
  return ctx;
}

}  // namespace trellis::detail
