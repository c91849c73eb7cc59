// bind_view.cpp — trellis_mech.view: the viewer page (trellis/viewer/view.hpp) from Python; in a
// Jupyter notebook it is also displayed inline.
#include "common.hpp"

#include "trellis/core/io.hpp"
#include "trellis/core/scene.hpp"
#include "trellis/viewer/view.hpp"

#include <pybind11/stl.h>

#include <filesystem>

namespace trellis::python {
namespace {

/// True inside a Jupyter kernel (IPython with a kernel app), where display() shows HTML.
bool inNotebook() {
  try {
    const py::object getIpython = py::module_::import("IPython").attr("get_ipython");
    const py::object shell = getIpython();
    return !shell.is_none() && py::hasattr(shell, "kernel");
  } catch (const py::error_already_set&) {
    return false;  // no IPython
  }
}

void displayInline(const std::string& page) {
  const py::object escape = py::module_::import("html").attr("escape");
  const std::string frame = "<iframe style=\"width: 100%; height: 520px; border: 0\" srcdoc=\"" +
                            escape(page, true).cast<std::string>() + "\"></iframe>";
  const py::module_ display = py::module_::import("IPython.display");
  display.attr("display")(display.attr("HTML")(frame));
}

}  // namespace

void bindView(py::module_& m) {
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ViewError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    }
  });
  m.def(
      "view",
      [](py::object model, py::args arguments, py::object pathArgument, py::object q,
         std::vector<std::string> names, double rate, const std::string& title, std::vector<std::string> packagePath,
         bool allSolid, py::object show) {
        // view(model, t1, t2, path=...) or view(model, t1, t2, "page.html"): the path as keyword,
        // or as the last positional argument (a str or os.PathLike).
        const py::object fspath = py::module_::import("os").attr("fspath");
        py::list trajectories;
        for (const py::handle a : arguments) trajectories.append(a);
        if (pathArgument.is_none()) {
          const bool last = !trajectories.empty() && (py::isinstance<py::str>(trajectories[trajectories.size() - 1]) ||
                                                      py::hasattr(trajectories[trajectories.size() - 1], "__fspath__"));
          if (!last) throw py::type_error("view: no path (give path=\"page.html\" or a path as the last argument)");
          pathArgument = trajectories[trajectories.size() - 1];
          trajectories.attr("pop")();
        }
        const std::string path = fspath(pathArgument).cast<std::string>();
        // The model: a scene or URDF file (keeps URDF visuals and resolves meshes against its
        // directory), a Scene (its stored q), or a Model.
        Scene scene{Model{}, {}, {}, {}, {}, {}, {}};
        ViewOptions options;
        if (py::isinstance<py::str>(model) || py::hasattr(model, "__fspath__")) {
          const std::string file = fspath(model).cast<std::string>();
          scene = loadScene(file);
          const std::filesystem::path parent = std::filesystem::path(file).parent_path();
          options.meshBaseDirectory = parent.empty() ? "." : parent.string();
        } else {
          const bool isScene = py::hasattr(model, "model") && py::hasattr(model, "q");
          scene.model = *(isScene ? model.attr("model") : model).cast<ModelPtr>();
          scene.q = isScene ? model.attr("q").cast<Eigen::VectorXd>() : Eigen::VectorXd::Zero(scene.model.nq());
          scene.name = scene.model.name();
        }
        Eigen::VectorXd shown = q.is_none() ? scene.q : q.cast<Eigen::VectorXd>();
        if (shown.size() != scene.model.nq()) {
          throw py::value_error("view: q has " + std::to_string(shown.size()) + " entries, the model has nq = " +
                                std::to_string(scene.model.nq()));
        }
        if (!names.empty() && names.size() != trajectories.size()) {
          throw py::value_error("view: " + std::to_string(names.size()) + " names for " +
                                std::to_string(trajectories.size()) + " trajectories");
        }
        std::vector<ViewTrajectory> list;
        for (std::size_t i = 0; i < trajectories.size(); ++i) {
          ViewTrajectory t;
          t.trajectory = trajectories[i].cast<Trajectory>();
          t.name = names.empty() ? (i == 0 ? std::string("reference") : "trajectory " + std::to_string(i + 1)) : names[i];
          t.ghost = i > 0 && !allSolid;
          list.push_back(std::move(t));
        }
        options.displayRate = rate;
        options.title = title;
        options.packagePath = std::move(packagePath);
        ViewReport report;
        std::string page;
        {
          py::gil_scoped_release release;
          page = renderView(scene, shown, list, options, &report);
        }
        writeFileAtomically(path, page);
        const py::object warn = py::module_::import("warnings").attr("warn");
        for (const std::string& w : report.warnings) warn(w);
        if (show.is_none() ? inNotebook() : show.cast<bool>()) displayInline(page);
        return pathArgument;
      },
      py::arg("model"), py::kw_only(), py::arg("path") = py::none(), py::arg("q") = py::none(),
      py::arg("names") = std::vector<std::string>{}, py::arg("rate") = 60.0, py::arg("title") = "",
      py::arg("package_path") = std::vector<std::string>{}, py::arg("all_solid") = false,
      py::arg("show") = py::none(),
      R"(view(model, *trajectories, path=None, q=None, names=[], rate=60.0, title="", package_path=[], all_solid=False, show=None)

Writes a self-contained HTML page (three.js included) that shows the model in 3D in a browser,
with a time slider, play/pause, speed and looping when trajectories are given: the first drawn
solid, the others ghosted (all_solid=True: all solid). The same page as `trellis view`
(docs/viewer.md); poses are the library's kinematics, sampled at every knot and `rate` times per
second. `model`: a scene or URDF file path (keeps URDF visual geometry, meshes relative to the
file), a Scene (shown at its stored q) or a Model (at q = 0); `path`: the page to write, as a
keyword or as the last positional argument (str or os.PathLike); `q` overrides the configuration
shown without trajectories. The file is written atomically. In a Jupyter notebook (or show=True)
the page is also displayed inline. Returns `path`. Raises ValueError (a trajectory that does not
match the model, a bad visual, an unreadable mesh, three.js missing) and warns (warnings.warn)
when a mesh is drawn as a stand-in.)");
}

}  // namespace trellis::python
