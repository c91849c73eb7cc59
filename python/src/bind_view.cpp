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

/// What view() returns: the written page. os.PathLike (its path), and _repr_html_ for Jupyter,
/// which calls it to show the object inline (no IPython needed here).
struct ViewPage {
  std::string path, html;
  long samples = 0;
  std::vector<std::string> warnings;
};

/// The page inside an iframe (srcdoc: the page itself, HTML-escaped; no server, no file access).
std::string iframe(const std::string& page, int height) {
  const py::object escape = py::module_::import("html").attr("escape");
  return "<iframe style=\"width: 100%; height: " + std::to_string(height) + "px; border: 0\" srcdoc=\"" +
         escape(page, true).cast<std::string>() + "\"></iframe>";
}

}  // namespace

void bindView(py::module_& m) {
  py::class_<ViewPage>(m, "ViewPage",
                       "The page view() wrote: os.PathLike (its path); shown inline in a Jupyter notebook "
                       "(_repr_html_: the page in an iframe).")
      .def_readonly("path", &ViewPage::path, "the file written")
      .def_readonly("html", &ViewPage::html, "the page's text (what the file holds)")
      .def_readonly("samples", &ViewPage::samples, "pose samples over all trajectories (1 for a state)")
      .def_readonly("warnings", &ViewPage::warnings, "e.g. a mesh drawn as a stand-in (also given to warnings.warn)")
      .def("__fspath__", [](const ViewPage& p) { return p.path; })
      .def("__str__", [](const ViewPage& p) { return p.path; })
      .def("__repr__",
           [](const ViewPage& p) {
             return "<ViewPage " + p.path + " (" + std::to_string(p.html.size()) + " bytes, " +
                    std::to_string(p.samples) + " pose samples)>";
           })
      .def(
          "_repr_html_", [](const ViewPage& p, int height) { return iframe(p.html, height); }, py::arg("height") = 520,
          "The page in an iframe (srcdoc), as Jupyter shows the object: the page is self-contained, so it "
          "needs neither a server nor the file.");
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
         bool allSolid, bool forces, bool show) {
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
        options.constraintForces = forces;
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
        ViewPage written{path, std::move(page), report.samples, report.warnings};
        if (show) {  // now, wherever the call is (Jupyter shows a returned ViewPage by itself)
          const py::module_ display = py::module_::import("IPython.display");
          display.attr("display")(display.attr("HTML")(iframe(written.html, 520)));
        }
        return written;
      },
      py::arg("model"), py::kw_only(), py::arg("path") = py::none(), py::arg("q") = py::none(),
      py::arg("names") = std::vector<std::string>{}, py::arg("rate") = 60.0, py::arg("title") = "",
      py::arg("package_path") = std::vector<std::string>{}, py::arg("all_solid") = false,
      py::arg("forces") = true, py::arg("show") = false,
      R"(view(model, *trajectories, path=None, q=None, names=[], rate=60.0, title="", package_path=[], all_solid=False, forces=True, show=False)

Writes a self-contained HTML page (three.js included) that shows the model in 3D in a browser,
with a time slider, play/pause, speed and looping when trajectories are given: the first drawn
solid, the others ghosted (all_solid=True: all solid). The same page as `trellis view`
(docs/viewer.md); poses are the library's kinematics, sampled at every knot and `rate` times per
second. `model`: a scene or URDF file path (keeps URDF visual geometry, meshes relative to the
file), a Scene (shown at its stored q) or a Model (at q = 0); `path`: the page to write, as a
keyword or as the last positional argument (str or os.PathLike); `q` overrides the configuration
shown without trajectories. The file is written atomically. Returns a ViewPage: os.PathLike (the
path), and shown inline by Jupyter when it is a cell's value (its _repr_html_ embeds the page in an
iframe); show=True displays it at once through IPython.display. With constraints, the solid
trajectories' constraint forces are drawn as arrows (forces=False: none). Raises ValueError (a trajectory that does not
match the model, a bad visual, an unreadable mesh, three.js missing) and warns (warnings.warn)
when a mesh is drawn as a stand-in.)");
}

}  // namespace trellis::python
