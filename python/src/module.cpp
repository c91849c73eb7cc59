// python/src/module.cpp — the extension module _trellis_mech (imported by trellis_mech/__init__.py),
// the shared conversion helpers, and the translation of C++ exceptions.
//
// Layout: one binding file per public header group, not per header and not per library. A group
// is the headers a Python user reaches for together and whose types refer to each other: the core
// model, workspace and algorithms (bind_core.cpp), the second-order derivatives
// (bind_second_order.cpp), trajectories and gain schedules (bind_trajectory.cpp), the
// time-invariant LQR tools (algebraic Riccati, Lyapunov, zero-order hold, discrete recursion:
// bind_lqr.cpp), controllability (bind_controllability.cpp), the one TV-LQR entry with its
// options (tvlqr.hpp and the option structs of riccati.hpp, sampled_lqr.hpp, manifold_lqr.hpp:
// bind_tvlqr.cpp), simulation (bind_simulation.cpp), optimization, the viewer and the hand
// example. Per header would split one user-facing call from its options (solve_tvlqr needs four
// option headers); per library would put the unrelated CARE and the simulator in one 700-line
// file, as before.
//
// Arrays: one axis rule, time first — an array of samples is (N, ...), row k at t_k (the package
// docstring states it). Results: every result type exposes `status` (the C++ Status: code as the
// enum's name, message, t, index), `ok`, and the library's describe() / json() reports.
//
// Exceptions: bad input becomes ValueError — plain std::invalid_argument / std::out_of_range /
// std::logic_error, and the descriptive trellis types ModelError, TrajectoryError, ProblemError,
// which are ValueError subclasses here. A trellis::FileError (a file that cannot be read or written)
// becomes OSError with the errno its message names, so that Python picks the subclass
// (FileNotFoundError, PermissionError, IsADirectoryError, …). A std::runtime_error the C++ throws
// for a numerical failure
// (what remains: e.g. a zero-order hold whose exponential overflows) becomes
// trellis_mech.NumericalError (a RuntimeError). Failures the C++ reports as a status stay a status.
#include "common.hpp"

#include "trellis/core/io.hpp"
#include "trellis/core/trajectory.hpp"
#include "trellis/core/model_builder.hpp"
#include "trellis/optimization/problem.hpp"

#include <bit>
#include <cerrno>
#include <cstring>
#include <string>

namespace trellis::python {

void checkSameModel(const Model& model, const PyData& data) {
  if (&model != data.model.get()) {
    throw std::invalid_argument("data: this Data was made for another model ('" +
                                data.model->name() + "'); make one with trellis_mech.Data(model)");
  }
}

void checkSize(Eigen::Index got, Eigen::Index expected, const char* name, const char* sizeName) {
  if (got != expected) {
    throw std::invalid_argument(std::string(name) + ": expected " + std::to_string(expected) +
                                " entries (" + sizeName + "), got " + std::to_string(got));
  }
}

void loadVector(const VectorRef& v, Eigen::VectorXd& dst, const char* name, const char* sizeName) {
  checkSize(v.size(), dst.size(), name, sizeName);
  dst = v;  // same size: no allocation
}

py::object toArrayComplex(const Eigen::VectorXcd& v) {
  // Returned as complex128 through pybind11's Eigen caster (a copy).
  return py::cast(Eigen::VectorXcd(v));
}

py::array_t<double> toArray3(const std::vector<Eigen::MatrixXd>& ms, Eigen::Index rows,
                             Eigen::Index cols) {
  py::array_t<double> a({static_cast<Eigen::Index>(ms.size()), rows, cols});
  auto r = a.mutable_unchecked<3>();
  for (std::size_t k = 0; k < ms.size(); ++k) {
    for (Eigen::Index i = 0; i < rows; ++i) {
      for (Eigen::Index j = 0; j < cols; ++j) r(k, i, j) = ms[k](i, j);
    }
  }
  return a;
}

StridedMap outputMap(py::array& out, Eigen::Index rows, Eigen::Index cols, const char* name) {
  // Read straight from the array struct (no Python objects created: this is the hot path).
  auto* arr = py::detail::array_proxy(out.ptr());
  auto* descr = py::detail::array_descriptor_proxy(arr->descr);
  const auto fail = [&](const std::string& what) {
    return std::invalid_argument(std::string("out ") + name + ": " + what);
  };
  if (descr->type_num != py::detail::npy_api::NPY_DOUBLE_) {
    throw fail("must be a float64 numpy array, got dtype " + std::string(py::str(out.dtype())));
  }
  constexpr char kSwapped = std::endian::native == std::endian::little ? '>' : '<';
  if (descr->byteorder == kSwapped) throw fail("must be in native byte order");
  if (!(arr->flags & py::detail::npy_api::NPY_ARRAY_WRITEABLE_)) throw fail("is read-only");
  const bool vector = cols < 0;
  if (arr->nd != (vector ? 1 : 2) || arr->dimensions[0] != rows ||
      (!vector && arr->dimensions[1] != cols)) {
    const std::string expected =
        vector ? "(" + std::to_string(rows) + ",)"
               : "(" + std::to_string(rows) + ", " + std::to_string(cols) + ")";
    std::string got = "(";
    for (int i = 0; i < arr->nd; ++i) got += (i ? ", " : "") + std::to_string(arr->dimensions[i]);
    got += arr->nd == 1 ? ",)" : ")";
    throw fail("expected shape " + expected + ", got " + got);
  }
  const auto rowStride = arr->strides[0], colStride = vector ? 0 : arr->strides[1];
  if (rowStride % static_cast<py::ssize_t>(sizeof(double)) != 0 ||
      colStride % static_cast<py::ssize_t>(sizeof(double)) != 0) {
    throw fail("strides are not multiples of 8 bytes");
  }
  // Eigen's Stride<outer, inner>: column-major map, outer = column step, inner = row step.
  return StridedMap(reinterpret_cast<double*>(arr->data), rows, vector ? 1 : cols,
                    Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(colStride / 8, rowStride / 8));
}

namespace {
PyObject* gModelError = nullptr;
PyObject* gTrajectoryError = nullptr;
PyObject* gProblemError = nullptr;
PyObject* gNumericalError = nullptr;

/// Raises OSError for a FileError. Its message is "path: action (reason)" with the reason the
/// C library's text for an errno (describeOsError in core/src/io.cpp), so the errno is found by
/// matching that text; OSError(errno, message) then is the errno's subclass. A message without
/// a known reason ("path: is a directory, not a …") stays a plain OSError.
void setOsError(const FileError& e) {
  static constexpr int kCodes[] = {ENOENT, EACCES, EPERM,  EISDIR, ENOTDIR, EEXIST,       EROFS,
                                   ENOSPC, EFBIG,  EDQUOT, EIO,    ELOOP,   ENAMETOOLONG, EMFILE};
  const std::string_view what = e.what();
  for (const int code : kCodes) {
    if (what.ends_with("(" + std::string(std::strerror(code)) + ")")) {
      PyObject* error = PyObject_CallFunction(PyExc_OSError, "is", code, e.what());
      if (!error) return;  // the call's own exception is set
      PyErr_SetObject(reinterpret_cast<PyObject*>(Py_TYPE(error)), error);
      Py_DECREF(error);
      return;
    }
  }
  PyErr_SetString(PyExc_OSError, e.what());
}

PyObject* newError(py::module_& m, const char* name, PyObject* base, const char* doc) {
  const std::string qualified = std::string("trellis_mech.") + name;
  // One reference is kept for the life of the process (exception types are never unloaded).
  PyObject* type = PyErr_NewExceptionWithDoc(qualified.c_str(), doc, base, nullptr);
  if (!type) throw py::error_already_set();
  m.attr(name) = py::handle(type);
  return type;
}
}  // namespace

void bindErrors(py::module_& m) {
  gModelError = newError(m, "ModelError", PyExc_ValueError,
                         "Invalid model description (builder call or scene file); the message names "
                         "the element, the field and the value.");
  gTrajectoryError = newError(m, "TrajectoryError", PyExc_ValueError,
                              "Invalid trajectory or gain schedule (arrays or CSV); the message "
                              "names the row and column.");
  gProblemError = newError(m, "ProblemError", PyExc_ValueError,
                           "Invalid optimal control problem (object or problem file); the message "
                           "names the field and the value.");
  gNumericalError = newError(m, "NumericalError", PyExc_RuntimeError,
                             "A numerical failure that the C++ API throws (not a status): e.g. the "
                             "dynamics fail where a function needs them, a singular Lyapunov "
                             "equation.");
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const py::builtin_exception&) {
      throw;  // pybind11's own (value_error, index_error, …): its default translation
    } catch (const py::error_already_set&) {
      throw;
    } catch (const DataInUseError& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    } catch (const ModelError& e) {
      PyErr_SetString(gModelError, e.what());
    } catch (const TrajectoryError& e) {
      PyErr_SetString(gTrajectoryError, e.what());
    } catch (const ProblemError& e) {
      PyErr_SetString(gProblemError, e.what());
    } catch (const FileError& e) {  // a file that cannot be read or written: OSError, as open() gives
      setOsError(e);
    } catch (const std::logic_error& e) {  // invalid_argument, out_of_range, domain_error, …
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const std::runtime_error& e) {
      PyErr_SetString(gNumericalError, e.what());
    }
  });
}

}  // namespace trellis::python

namespace trellis::python { void bindView(py::module_& m); }  // bind_view.cpp: trellis_mech.view

PYBIND11_MODULE(_trellis_mech, m) {
  namespace tp = trellis::python;
  m.doc() = "trellis: exact linearizations of constrained mechanical systems, TV-LQR and "
            "trajectory optimization (C++ core; see the trellis_mech package docstring)";
  tp::bindErrors(m);
  tp::bindCore(m);
  tp::bindSecondOrder(m);
  tp::bindTrajectory(m);
  tp::bindLqr(m);
  tp::bindControllability(m);
  tp::bindTvlqr(m);
  tp::bindSimulation(m);
  tp::bindFunnel(m);
  tp::bindOptimization(m);
  tp::bindView(m);
#ifdef TRELLIS_PYTHON_HAND
  tp::bindHand(m);
#endif
}
