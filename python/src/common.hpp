// python/src/common.hpp — conversions shared by the binding files (core, control, optimization).
//
// Arrays in: vectors and matrices are taken as Eigen::Ref<const …> or by value, so any array-like
// convertible to float64 is accepted; a float64 array that is contiguous in the right order is
// read in place, anything else (other dtype, C-order matrix where column-major is needed,
// non-contiguous slices, lists) is copied first. Arrays out: fresh C-order float64 NumPy arrays
// (copies — the result owns its memory), or, for the hot-loop `out` arguments, the caller's
// float64 array of the exact shape in any memory order (strided writes, no allocation).
#pragma once

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "trellis/core/data.hpp"
#include "trellis/core/model.hpp"
#include "trellis/core/status.hpp"

#include <Eigen/Core>

#include <atomic>
#include <memory>
#include <stdexcept>
#include <string>

namespace trellis::python {

namespace py = pybind11;

using ModelPtr = std::shared_ptr<Model>;
using VectorRef = Eigen::Ref<const Eigen::VectorXd>;
using StridedMap = Eigen::Map<Eigen::MatrixXd, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

/// Throws TypeError when `src` is a NumPy array of complex numbers: converting it to float64 would
/// keep the real part and drop the rest with only a warning. `argument` names it when known.
inline void refuseComplex(py::handle src, const char* argument = nullptr,
                          const char* expected = "a real (float64) array") {
  if (py::isinstance<py::array>(src) && py::reinterpret_borrow<py::array>(src).dtype().kind() == 'c') {
    const std::string dtype = py::str(py::reinterpret_borrow<py::array>(src).dtype());
    throw py::type_error((argument ? std::string(argument) + ": got" : std::string("got")) +
                         " a complex array (" + dtype + ") where " + expected +
                         " is expected; pass .real (or .imag) explicitly if that is what you mean");
  }
}

/// A compile-time argument name (C++20 class-type template parameter): RealMatrix<"A">.
template <std::size_t N>
struct ArgName {
  char text[N];
  constexpr ArgName(const char (&s)[N]) {  // NOLINT(google-explicit-constructor): "A" → name
    for (std::size_t i = 0; i < N; ++i) text[i] = s[i];
  }
};

/// A real matrix argument that knows its name: read as pybind11 reads an Eigen::MatrixXd (any
/// array-like convertible to float64, copied), except that a complex array is a TypeError naming
/// the argument (refuseComplex). Use `.value` (or the implicit conversion).
template <ArgName Name>
struct RealMatrix {
  Eigen::MatrixXd value;
  operator const Eigen::MatrixXd&() const { return value; }  // NOLINT(google-explicit-constructor)
};

/// A real vector argument that knows its name: read as the Eigen::Ref<const VectorXd> caster reads
/// it (a contiguous float64 array in place, anything else converted), except that a complex array
/// is a TypeError naming the argument (refuseComplex). `.ref` (or the implicit conversion) is the
/// vector. (A wrapper, not a Ref subclass: pybind11's own Eigen casters would claim a subclass.)
template <ArgName Name>
struct RealVector {
  Eigen::Ref<const Eigen::VectorXd> ref;
  operator const Eigen::Ref<const Eigen::VectorXd>&() const { return ref; }  // NOLINT(google-explicit-constructor)
  Eigen::Index size() const { return ref.size(); }
};

/// The Status of a result as a Python class `name`: code (the C++ enum's name, a str such as
/// "blow_up" — enum_names.hpp), message, t (float; NaN: no time), index (int; -1: none), ok, and
/// describe() (the one line of Status::describe).
template <class Code>
py::class_<Status<Code>> bindStatus(py::module_& m, const char* name, const char* doc) {
  return py::class_<Status<Code>>(m, name, doc)
      .def_property_readonly("code", [](const Status<Code>& s) { return std::string(s.name()); },
                             "the code's name (str): 'ok', or what failed")
      .def_readonly("message", &Status<Code>::message, "empty when ok; what failed, with the values")
      .def_readonly("t", &Status<Code>::t, "when it happened (NaN: not applicable)")
      .def_readonly("index", &Status<Code>::index, "where: knot, step, interval or row (-1: none)")
      .def_property_readonly("ok", &Status<Code>::ok)
      .def("describe", &Status<Code>::describe)
      .def("__repr__", [name](const Status<Code>& s) { return "<" + std::string(name) + " " + s.describe() + ">"; });
}

/// The Python `Data`: the core workspace, the model it was sized for (kept alive), input buffers
/// (so a call copies q, q̇, u into preallocated vectors instead of allocating), and a flag that
/// refuses concurrent use from two threads (calls release the GIL).
struct PyData {
  explicit PyData(ModelPtr m)
      : model(std::move(m)), data(*model), q(model->nq()), dq(model->nq()), u(model->nu()) {
    q.setZero();
    dq.setZero();
    u.setZero();
  }
  ModelPtr model;
  Data data;
  Eigen::VectorXd q, dq, u;
  std::atomic<bool> busy{false};
};

/// Two threads using one Data at once (translated to RuntimeError, not NumericalError).
class DataInUseError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Marks a PyData in use for the lifetime of the guard; throws if another thread holds it.
class DataGuard {
 public:
  explicit DataGuard(PyData& d) : d_(d) {
    if (d_.busy.exchange(true)) {
      throw DataInUseError(
          "Data is in use by another thread: use one Data per thread (trellis_mech.Data(model))");
    }
  }
  ~DataGuard() { d_.busy.store(false); }
  DataGuard(const DataGuard&) = delete;
  DataGuard& operator=(const DataGuard&) = delete;

 private:
  PyData& d_;
};

/// Throws std::invalid_argument unless data was built for model (same object).
void checkSameModel(const Model& model, const PyData& data);

/// Copies v into dst (already sized `expected`) after checking its size; names the argument.
void loadVector(const VectorRef& v, Eigen::VectorXd& dst, const char* name, const char* sizeName);
/// Size check only (message names the argument and the model size it must match).
void checkSize(Eigen::Index got, Eigen::Index expected, const char* name, const char* sizeName);

/// A fresh NumPy array (C order) holding a copy of the matrix (2-D) or of the column vector
/// (1-D: any expression with one column at compile time).
template <class Derived>
py::array_t<double> toArray(const Eigen::MatrixBase<Derived>& m) {
  if constexpr (Derived::ColsAtCompileTime == 1) {
    py::array_t<double> a(m.size());
    Eigen::Map<Eigen::VectorXd>(a.mutable_data(), m.size()) = m;
    return a;
  } else {
    py::array_t<double> a({m.rows(), m.cols()});
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
        a.mutable_data(), m.rows(), m.cols()) = m;
    return a;
  }
}
py::object toArrayComplex(const Eigen::VectorXcd& v);  // complex128 (a copy)

/// A vector or matrix field of an options or problem struct as a property that copies in and out
/// (a NumPy view of the C++ buffer could dangle when the field is reassigned with another size);
/// assigning a complex array is a TypeError naming the field (never cut to its real part).
template <class Owner, class T, class PyClass>
void realArrayProperty(PyClass& cls, const char* name, T Owner::*member, const char* doc) {
  cls.def_property(
      name, [member](const Owner& o) { return toArray(o.*member); },
      [member, name](Owner& o, const py::object& value) {
        refuseComplex(value, name, T::ColsAtCompileTime == 1 ? "a real (float64) vector"
                                                             : "a real (float64) matrix");
        o.*member = value.cast<T>();
      },
      doc);
}

/// N matrices of equal size as one (N, rows, cols) array.
py::array_t<double> toArray3(const std::vector<Eigen::MatrixXd>& ms, Eigen::Index rows,
                             Eigen::Index cols);

/// The caller's output array as a strided Eigen map: must be a writeable float64 ndarray of
/// exactly rows×cols (2-D) — or `rows` entries when cols < 0 (1-D) — in any memory order.
/// Throws std::invalid_argument naming the argument otherwise.
StridedMap outputMap(py::array& out, Eigen::Index rows, Eigen::Index cols, const char* name);

/// Registers the exception types and the C++ → Python translation (module.cpp).
void bindErrors(py::module_& m);
void bindCore(py::module_& m);            // bind_core.cpp
void bindTrajectory(py::module_& m);      // bind_trajectory.cpp
void bindLqr(py::module_& m);             // bind_lqr.cpp
void bindControllability(py::module_& m); // bind_controllability.cpp
void bindTvlqr(py::module_& m);           // bind_tvlqr.cpp
void bindSimulation(py::module_& m);      // bind_simulation.cpp
void bindFunnel(py::module_& m);          // bind_funnel.cpp
void bindOptimization(py::module_& m);
void bindHand(py::module_& m);
void bindSecondOrder(py::module_& m);  // bind_second_order.cpp

/// The loader behind the vector casters (pybind11::detail below): reads a contiguous float64 array
/// in place (anything else converted, as pybind11's Eigen::Ref caster does) into a Ref of an
/// unaligned vector type (a distinct type, so pybind11's own caster serves it) that `Value` then
/// maps without a copy; a complex array is refused first (refuseComplex, naming `argument` when
/// it has one: argumentName). Value: Eigen::Ref<const VectorXd> or RealVector<"name">.
inline const char* argumentName(const Eigen::Ref<const Eigen::VectorXd>*) { return nullptr; }
template <ArgName Name>
const char* argumentName(const RealVector<Name>*) { return Name.text; }
template <class Value>
struct RealVectorRefCaster {
  using InnerRef = Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::DontAlign>>;

  bool load(py::handle src, bool convert) {
    refuseComplex(src, argumentName(static_cast<const Value*>(nullptr)), "a real (float64) vector");
    if (!inner_.load(src, convert)) return false;
    const InnerRef& mapped = inner_;
    ref_ = std::make_unique<Value>(Value{Eigen::Ref<const Eigen::VectorXd>(mapped)});
    return true;
  }
  static constexpr auto name = py::detail::type_caster<InnerRef>::name;
  // NOLINTNEXTLINE(google-explicit-constructor)
  operator Value*() { return ref_.get(); }
  // NOLINTNEXTLINE(google-explicit-constructor)
  operator Value&() { return *ref_; }
  template <typename T>
  using cast_op_type = py::detail::cast_op_type<T>;

 private:
  py::detail::type_caster<InnerRef> inner_;
  std::unique_ptr<Value> ref_;
};

}  // namespace trellis::python

namespace pybind11::detail {

/// By-value real vectors and matrices (Eigen::VectorXd, Eigen::MatrixXd: times, bounds, options'
/// and problems' fields) read as pybind11 reads them — any array-like converted to float64, copied —
/// except that a complex array is refused (refuseComplex) instead of cast to its real part with
/// only a NumPy warning. Loading goes through pybind11's caster of the unaligned type of the same
/// shape (a distinct type, so pybind11's own caster serves it); returning goes through its caster of
/// a Map of the value: a reference to it (reference, reference_internal: the array of a member, kept
/// alive by its owner, read-only as before) or a copy (every other policy).
template <class Plain>
struct RealPlainCaster {
  using Unaligned = Eigen::Matrix<double, Plain::RowsAtCompileTime, Plain::ColsAtCompileTime,
                                  Eigen::DontAlign | Eigen::ColMajor>;
  using ConstMap = Eigen::Map<const Plain>;
  PYBIND11_TYPE_CASTER(Plain, type_caster<Unaligned>::name);

  bool load(handle src, bool convert) {
    trellis::python::refuseComplex(src);
    type_caster<Unaligned> inner;
    if (!inner.load(src, convert)) return false;
    const Unaligned& read = inner;
    value = read;
    return true;
  }
  static handle cast(const Plain& src, return_value_policy policy, handle parent) {
    const ConstMap map(src.data(), src.rows(), src.cols());
    const bool byReference =
        policy == return_value_policy::reference || policy == return_value_policy::reference_internal;
    return type_caster<ConstMap>::cast(map, byReference ? policy : return_value_policy::copy, parent);
  }
};
template <>
struct type_caster<Eigen::VectorXd> : RealPlainCaster<Eigen::VectorXd> {};
template <>
struct type_caster<Eigen::MatrixXd> : RealPlainCaster<Eigen::MatrixXd> {};

/// Vector arguments as pybind11's own Eigen::Ref caster reads them (a contiguous float64 array in
/// place, anything else converted), except that a complex array is refused instead of cast to its
/// real part (trellis::python::RealVectorRefCaster).
template <>
struct type_caster<Eigen::Ref<const Eigen::VectorXd>>
    : trellis::python::RealVectorRefCaster<Eigen::Ref<const Eigen::VectorXd>> {};

/// RealVector<"name">: the same caster, naming the argument in the complex refusal.
template <trellis::python::ArgName Name>
struct type_caster<trellis::python::RealVector<Name>>
    : trellis::python::RealVectorRefCaster<trellis::python::RealVector<Name>> {};

/// RealMatrix<"name">: the Eigen::MatrixXd caster after the complex check (naming the argument).
template <trellis::python::ArgName Name>
struct type_caster<trellis::python::RealMatrix<Name>> {
  using Value = trellis::python::RealMatrix<Name>;
  PYBIND11_TYPE_CASTER(Value, type_caster<Eigen::MatrixXd>::name);

  bool load(handle src, bool convert) {
    trellis::python::refuseComplex(src, Name.text, "a real (float64) matrix");
    type_caster<Eigen::MatrixXd> inner;
    if (!inner.load(src, convert)) return false;
    value.value = std::move(static_cast<Eigen::MatrixXd&>(inner));
    return true;
  }
  static handle cast(const Value& v, return_value_policy policy, handle parent) {
    return type_caster<Eigen::MatrixXd>::cast(v.value, policy, parent);
  }
};

}  // namespace pybind11::detail
