// tuile._tuile: the renderer from Python (pybind11). The pure-Python package around it
// (python/tuile/__init__.py, plot.py) gives the documented API; see docs/python.md.
//
// Flags are the command line's: a keyword argument `light_pick="bvh"` is parsed as
// `--light-pick bvh` by the same CLI11 definitions as `tuile render`, so every flag and
// every check of the command line is the module's too, and the same flags give the same
// bits. Renders run on a worker thread with the GIL released; the calling thread polls for
// signals every 20 ms and, on KeyboardInterrupt, stops the render at the next tile
// boundary and raises.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <iostream>
#include <mutex>
#include <regex>
#include <thread>

#include "accel/embree.h"
#include "app/cli.h"
#include "app/commands.h"
#include "app/prepare.h"
#include "app/render_job.h"
#include "render/render.h"
#include "scene/atomic_file.h"
#include "scene/image_io.h"
#include "scene/scene.h"

namespace py = pybind11;
using namespace tuile;

namespace {

// "--light-pick" in a message of the command line's as the keyword argument "light_pick".
std::string python_names(const std::string& msg) {
  static const std::regex flag("--([a-z][a-z0-9-]*)");
  std::string out;
  std::sregex_iterator it(msg.begin(), msg.end(), flag), end;
  size_t last = 0;
  for (; it != end; ++it) {
    out += msg.substr(last, static_cast<size_t>(it->position()) - last);
    std::string name = (*it)[1].str();
    for (char& c : name)
      if (c == '-') c = '_';
    if (name == "aov") name = "aovs";
    out += name;
    last = static_cast<size_t>(it->position() + it->length());
  }
  return out + msg.substr(last);
}

[[noreturn]] void value_error(const std::string& where, const std::string& msg) {
  throw py::value_error(where + ": " + python_names(msg));
}

// Keyword arguments to the command line's tokens. `aovs` is --aov (a list or a comma-
// separated string), `res` "WxH" or (W, H); True is the flag, False --flag=false; None
// is left out; numbers as Python writes them (repr: a float's shortest round trip).
std::vector<std::string> to_args(const std::string& where, CLI::App& app, const py::kwargs& kw) {
  std::vector<std::string> args;
  for (auto item : kw) {
    std::string name = py::cast<std::string>(item.first);
    py::handle v = item.second;
    if (v.is_none()) continue;
    std::string flag = name == "aovs" ? "aov" : name;
    for (char& c : flag)
      if (c == '_') c = '-';
    if (name.find('-') != std::string::npos || app.get_option_no_throw("--" + flag) == nullptr) {
      std::string known;
      for (const CLI::Option* o : app.get_options()) {
        std::string n = o->get_name(false, true);
        if (n.rfind("--", 0) != 0 || n == "--help") continue;
        n = n.substr(2);
        for (char& c : n)
          if (c == '-') c = '_';
        if (n == "aov") n = "aovs";
        known += (known.empty() ? "" : ", ") + n;
      }
      throw py::value_error(where + ": unknown argument '" + name + "' (known: " + known + ")");
    }
    std::string value;
    const CLI::Option* opt = app.get_option_no_throw("--" + flag);
    const std::string type_name = py::cast<std::string>(py::str(py::type::of(v).attr("__name__")));
    if (py::isinstance<py::bool_>(v) || type_name == "bool_") {  // (numpy's bool too)
      // (True for a flag; an option that needs a value took the next argument as it: spp=True)
      if (opt->get_expected_min() > 0)
        throw py::value_error(where + ": " + name + ": expected a value, not " + (v.cast<bool>() ? "True" : "False"));
      args.push_back("--" + flag + (v.cast<bool>() ? "" : "=false"));
      continue;
    } else if (py::isinstance<py::str>(v)) {
      value = v.cast<std::string>();
    } else if (py::isinstance<py::int_>(v) || py::isinstance<py::float_>(v)) {
      value = py::cast<std::string>(py::repr(v));
    } else if (PyIndex_Check(v.ptr())) {  // numpy's integers
      value = py::cast<std::string>(py::repr(py::int_(py::reinterpret_borrow<py::object>(v))));
    } else if (py::hasattr(v, "__float__") && !py::isinstance<py::sequence>(v)) {  // numpy's floats
      value = py::cast<std::string>(py::repr(py::float_(py::reinterpret_borrow<py::object>(v))));
    } else if (name == "res" && (py::isinstance<py::tuple>(v) || py::isinstance<py::list>(v)) && py::len(v) == 2) {
      const py::sequence s = v.cast<py::sequence>();
      if (!py::isinstance<py::int_>(s[0]) || !py::isinstance<py::int_>(s[1]))
        throw py::value_error(where + ": res: expected (width, height) as two integers or 'WxH'");
      value = py::cast<std::string>(py::repr(s[0])) + "x" + py::cast<std::string>(py::repr(s[1]));
    } else if (name == "aovs" && (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v))) {
      for (py::handle a : v.cast<py::sequence>()) {
        if (!py::isinstance<py::str>(a)) throw py::value_error(where + ": aovs: expected a list of names (variance, mis_weight)");
        value += (value.empty() ? "" : ",") + a.cast<std::string>();
      }
      if (value.empty()) continue;
    } else {
      throw py::value_error(where + ": " + name + ": expected a number or a string, not " +
                            py::cast<std::string>(py::str(py::type::of(v).attr("__name__"))));
    }
    args.push_back("--" + flag + "=" + value);  // (one token: a flag with a value, --light-paths=off, too)
  }
  return args;
}

void parse(const std::string& where, CLI::App& app, const py::kwargs& kw) {
  const std::vector<std::string> args = to_args(where, app, kw);
  std::vector<const char*> argv = {"tuile"};
  for (const std::string& a : args) argv.push_back(a.c_str());
  try {
    app.parse(static_cast<int>(argv.size()), argv.data());
  } catch (const CLI::ParseError& e) {
    value_error(where, e.what());
  }
}

// The call as it would be written, for an EXR's commandLine.
std::string call_text(const std::string& source, const std::string& what, const py::kwargs& kw) {
  std::string s = "tuile.load(" + py::cast<std::string>(py::repr(py::str(source))) + ")." + what + "(";
  bool first = true;
  for (auto item : kw) {
    s += (first ? "" : ", ") + py::cast<std::string>(item.first) + "=" + py::cast<std::string>(py::repr(item.second));
    first = false;
  }
  return s + ")";
}

// Runs `work` on a worker thread with the GIL released. The calling thread checks for
// Python signals every 20 ms; on one (KeyboardInterrupt from SIGINT) it sets `cancel`,
// waits for the work to stop and throws the Python exception. The work's own exception is
// rethrown in the caller. Returns whether it was interrupted (then the Python error is set
// and the caller throws error_already_set after its own clean-up).
bool run_interruptible(const std::function<void()>& work, std::atomic<bool>& cancel) {
  std::mutex m;
  std::condition_variable cv;
  bool done = false, interrupted = false;
  std::exception_ptr err;
  {
    py::gil_scoped_release nogil;
    std::thread worker([&] {
      try {
        work();
      } catch (...) {
        err = std::current_exception();
      }
      std::lock_guard<std::mutex> g(m);
      done = true;
      cv.notify_all();
    });
    for (;;) {
      std::unique_lock<std::mutex> lk(m);
      if (cv.wait_for(lk, std::chrono::milliseconds(20), [&] { return done; })) break;
      lk.unlock();
      if (!interrupted) {
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {  // KeyboardInterrupt (or a handler's exception): now set
          interrupted = true;
          cancel.store(true);
        }
      }
    }
    worker.join();
  }
  if (err && !interrupted) std::rethrow_exception(err);
  return interrupted;
}

// Errors of the library as Python exceptions whose messages name keyword arguments.
template <class F> auto translating(const std::string& where, F&& fn) -> decltype(fn()) {
  try {
    return fn();
  } catch (const std::invalid_argument& e) {
    value_error(where, e.what());
  }
}

// A rendered film: the C++ film (double sums) and the images made from it. The arrays
// scene.render returns are views of `image` and `aovs` with this object as their base:
// they share its memory (no copy) and keep it alive.
struct PyFilm {
  Film film;
  std::vector<float> image, variance, mis_weight;
  double seconds = 0, setup_seconds = 0, estimated_error = 0;
  std::string stopped_by, estimator, pipeline;
  uint64_t samples_per_second = 0;
};

py::array view(const std::shared_ptr<PyFilm>& f, std::vector<float>& data, int channels) {
  py::object base = py::cast(f);
  const py::ssize_t h = f->film.height, w = f->film.width, c = channels;
  if (channels == 1)
    return py::array_t<float>({h, w}, {static_cast<py::ssize_t>(sizeof(float)) * w, static_cast<py::ssize_t>(sizeof(float))},
                              data.data(), base);
  return py::array_t<float>({h, w, c},
                            {static_cast<py::ssize_t>(sizeof(float)) * w * c, static_cast<py::ssize_t>(sizeof(float)) * c,
                             static_cast<py::ssize_t>(sizeof(float))},
                            data.data(), base);
}

// A scene loaded once, its BVH built once, rendered under any flags.
struct PyScene {
  std::shared_ptr<Prepared> p;
  std::string source;
  int width = 0, height = 0;  // the file's film (--res changes the loaded scene's camera)
  std::mutex busy;            // one render of a scene at a time (they share its camera)

  PyScene(const std::string& path, bool strict) {
    p = std::make_shared<Prepared>();
    const auto t0 = std::chrono::steady_clock::now();
    p->scene = load_scene(path, LoadOptions{strict});
    p->load_seconds = seconds_since(t0);
    const auto t1 = std::chrono::steady_clock::now();
    p->accel = std::make_unique<Accel>(p->scene);
    p->bvh_seconds = seconds_since(t1);
    source = p->scene.source;
    width = p->scene.camera.width;
    height = p->scene.camera.height;
  }

  std::unique_lock<std::mutex> claim() {
    std::unique_lock<std::mutex> lk(busy, std::try_to_lock);
    if (!lk.owns_lock()) throw std::runtime_error("this scene is rendering in another thread (load it again to render both at once)");
    p->scene.camera.width = width;
    p->scene.camera.height = height;
    return lk;
  }
};

py::object render(PyScene& s, const py::kwargs& kw) {
  const std::string where = "render()";
  RenderFlags f;
  f.quiet = true;  // Python is quiet unless asked: quiet=False prints the command's summary
  CLI::App app{"render"};
  add_render_flags(app, f);
  add_render_run_flags(app, f);
  app.add_option("-o,--output", f.output, "output .exr");
  if (kw.contains("scene")) throw py::value_error(where + ": scene: the scene is the object rendered (tuile.load)");
  if (kw.contains("strict")) throw py::value_error(where + ": strict: the scene is loaded already (tuile.load(path, strict=True))");
  parse(where, app, kw);
  f.scene = s.source;
  f.command_line = call_text(s.source, "render", kw);
  auto lk = s.claim();
  RenderJob job = translating(where, [&] { return start_render_job(f, s.p); });
  print_scene_warnings(f, job);
  std::atomic<bool> cancel{false};
  JobRun run;
  const bool interrupted = run_interruptible([&] { run = run_render_job(f, job, &cancel, !f.quiet); }, cancel);
  if (interrupted) {
    if (!job.out.empty()) {  // as the command line: the complete passes and a checkpoint
      py::gil_scoped_release nogil;
      finish_render_job(f, job, StopReason::cancelled, run.res.stats, run.seconds, run.estimated_error);
    }
    throw py::error_already_set();
  }
  if (!job.out.empty()) {
    py::gil_scoped_release nogil;
    finish_render_job(f, job, run.res.reason, run.res.stats, run.seconds, run.estimated_error);
  }
  auto out = std::make_shared<PyFilm>();
  out->film = std::move(job.film);
  out->image = out->film.mean();
  out->seconds = run.seconds;
  out->setup_seconds = job.setup_seconds;
  out->estimated_error = run.estimated_error;
  static const char* reasons[] = {"complete", "interrupted", "time-budget", "target-error", "failed"};
  out->stopped_by = reasons[static_cast<int>(run.res.reason)];
  out->estimator = describe(job.p->opt.est);
  out->pipeline = run.res.stats.pipeline;
  const RenderOptions& opt = job.p->opt;
  if (opt.aov_variance) out->variance = out->film.variance_of_mean();
  if (opt.aov_mis_weight) out->mis_weight = out->film.mis_weight();
  py::array image = view(out, out->image, 3);
  if (!opt.aov_variance && !opt.aov_mis_weight) return image;
  py::dict aovs;
  if (opt.aov_variance) aovs["variance"] = view(out, out->variance, 3);
  if (opt.aov_mis_weight) aovs["mis_weight"] = view(out, out->mis_weight, 1);
  return py::make_tuple(image, aovs);
}

std::string info(PyScene& s, const py::kwargs& kw) {
  const std::string where = "info()";
  RenderFlags f;
  CLI::App app{"info"};
  add_render_flags(app, f);
  parse(where, app, kw);
  auto lk = s.claim();
  return translating(where, [&] {
    s.p->opt = resolve_options(f, s.p->scene);
    return info_text(*s.p);
  });
}

std::vector<float> array_image(const py::array& a, const char* what) {
  const py::array_t<float, py::array::c_style | py::array::forcecast> f = a;
  if (f.ndim() != 3 || f.shape(2) != 3) throw py::value_error(std::string(what) + ": expected an (H, W, 3) array");
  return std::vector<float>(f.data(), f.data() + f.size());
}

py::object converge_py(PyScene& s, const py::object& strategies, const py::object& reference, bool images,
                       const py::kwargs& kw) {
  const std::string where = "converge()";
  ConvergeFlags f;
  f.render.quiet = true;
  CLI::App app{"converge"};
  add_render_flags(app, f.render);
  add_converge_flags(app, f);
  for (const char* k : {"scene", "csv", "plot", "reference", "strategies"})
    if (kw.contains(k))
      throw py::value_error(where + ": " + k + ": not a keyword of tuile.converge (plots: tuile.plot.error_vs_time)");
  parse(where, app, kw);
  if (py::isinstance<py::str>(strategies)) {
    f.strategies = strategies.cast<std::string>();
  } else if (!strategies.is_none()) {
    for (py::handle h : strategies) {
      if (!py::isinstance<py::str>(h)) throw py::value_error(where + ": strategies: expected a list of names");
      f.strategies += (f.strategies.empty() ? "" : ",") + h.cast<std::string>();
    }
    if (f.strategies.empty()) throw py::value_error(where + ": strategies: empty list");
  }
  std::vector<float> ref;
  if (py::isinstance<py::str>(reference)) {
    int w = 0, h = 0;
    const std::string path = reference.cast<std::string>();
    ref = read_exr(path, w, h);
  } else if (!reference.is_none()) {
    ref = array_image(reference.cast<py::array>(), "reference");
  }
  for (float x : ref)  // (a NaN in the reference made every row's error NaN)
    if (!std::isfinite(x)) throw py::value_error(where + ": reference: holds NaN or infinite values");
  auto lk = s.claim();
  std::atomic<bool> cancel{false};
  ConvergeResult res;
  const bool interrupted = translating(where, [&] {  // (its messages in the keywords' names, not the flags')
    return run_interruptible(
        [&] {
          try {
            res = converge(f, s.p->scene, *s.p->accel, std::move(ref), !f.render.quiet, &cancel);
          } catch (const ConvergeCancelled&) {
          }
        },
        cancel);
  });
  if (interrupted) throw py::error_already_set();
  py::list rows;
  for (const ConvergeRow& r : res.rows) {
    py::dict d;
    d["strategy"] = r.strategy;
    d["spp"] = r.spp;
    d["seconds"] = r.seconds;
    d["mse"] = r.mse;
    d["relmse"] = r.relmse;
    d["efficiency"] = r.efficiency;
    rows.append(d);
  }
  if (!images) return rows;
  py::dict imgs;
  auto to_array = [&](std::vector<float>& v) {
    py::array_t<float> a({res.height, res.width, 3});
    std::copy(v.begin(), v.end(), a.mutable_data());
    return a;
  };
  imgs["reference"] = to_array(res.reference);
  for (auto& im : res.images) imgs[py::str(im.first)] = to_array(im.second);
  return py::make_tuple(rows, imgs);
}

template <class Flags, class Add, class Run>
std::string measure(const std::string& where, const std::string& scene, const py::kwargs& kw, Add add, Run run) {
  Flags f;
  f.print = false;
  f.render.quiet = true;
  CLI::App app{where};
  add_render_flags(app, f.render);
  add(app, f);
  for (const char* k : {"scene", "json"})
    if (kw.contains(k)) throw py::value_error(where + ": " + k + ": not a keyword here (the result is the dict returned)");
  parse(where, app, kw);
  f.render.scene = scene;
  std::string json;
  translating(where, [&] {
    py::gil_scoped_release nogil;
    return run(f, &json);
  });
  return json;
}

}  // namespace

PYBIND11_MODULE(_tuile, m) {
  m.doc() = "tuile's renderer (the compiled part of the tuile package)";
  m.attr("__version__") = TUILE_VERSION;
  static py::exception<SceneError> scene_error(m, "SceneError", PyExc_ValueError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const SceneError& e) {
      scene_error(e.what());
    }
  });

  py::class_<PyFilm, std::shared_ptr<PyFilm>>(m, "Film", "A rendered film; the base of the arrays scene.render returns")
      .def_property_readonly("width", [](const PyFilm& f) { return f.film.width; })
      .def_property_readonly("height", [](const PyFilm& f) { return f.film.height; })
      .def_property_readonly("spp", [](const PyFilm& f) { return f.film.samples; })
      .def_readonly("seconds", &PyFilm::seconds)
      .def_readonly("setup_seconds", &PyFilm::setup_seconds)
      .def_readonly("stopped_by", &PyFilm::stopped_by)
      .def_readonly("estimated_error", &PyFilm::estimated_error)
      .def_readonly("estimator", &PyFilm::estimator)
      .def_readonly("pipeline", &PyFilm::pipeline)
      .def_property_readonly("image", [](const std::shared_ptr<PyFilm>& f) { return view(f, f->image, 3); })
      .def_property_readonly("image_address",
                             [](const PyFilm& f) { return reinterpret_cast<uintptr_t>(f.image.data()); });

  py::class_<PyScene>(m, "Scene", "A scene loaded and its BVH built (tuile.load)")
      .def(py::init([](const std::string& path, bool strict) {
             py::gil_scoped_release nogil;
             return new PyScene(path, strict);
           }),
           py::arg("path"), py::arg("strict") = false)
      .def_readonly("source", &PyScene::source)
      .def_readonly("width", &PyScene::width)
      .def_readonly("height", &PyScene::height)
      .def_property_readonly("warnings", [](const PyScene& s) { return s.p->scene.warnings; })
      .def("render", &render, "Renders the scene under the flags of `tuile render` (keyword arguments)")
      .def("_info", &info);

  m.def("_converge", &converge_py, py::arg("scene"), py::arg("strategies") = py::none(),
        py::arg("reference") = py::none(), py::arg("images") = false);
  m.def("_bench", [](const std::string& scene, const py::kwargs& kw) {
    return measure<BenchFlags>("bench()", scene, kw, add_bench_flags,
                               [](const BenchFlags& f, std::string* j) { return run_bench(f, j); });
  });
  m.def("_profile", [](const std::string& scene, const py::kwargs& kw) {
    return measure<ProfileFlags>("profile()", scene, kw, add_profile_flags,
                                 [](const ProfileFlags& f, std::string* j) { return run_profile(f, j); });
  });
  m.def("strategies", &converge_strategy_names, "The strategies tuile.converge knows (as `tuile converge --help` lists)");
  m.def(
      "read_exr",
      [](const std::string& path) {
        int w = 0, h = 0;
        std::vector<float> v;
        {
          py::gil_scoped_release nogil;
          v = read_exr(path, w, h);
        }
        py::array_t<float> a({h, w, 3});
        std::copy(v.begin(), v.end(), a.mutable_data());
        return a;
      },
      py::arg("path"), "An EXR's RGB as an (H, W, 3) float32 array");
  m.def(
      "write_exr",
      [](const std::string& path, const py::array& image) {
        const py::array_t<float, py::array::c_style | py::array::forcecast> f = image;
        if (f.ndim() != 3 || f.shape(2) != 3) throw py::value_error("write_exr: expected an (H, W, 3) array");
        try {  // (an EXR named .png, a folder: refused before writing)
          check_output_path(path, {".exr"});
        } catch (const std::invalid_argument& e) {
          throw py::value_error(std::string("write_exr: ") + e.what());
        }
        write_exr(path, static_cast<int>(f.shape(1)), static_cast<int>(f.shape(0)),
                  std::vector<float>(f.data(), f.data() + f.size()));
      },
      py::arg("path"), py::arg("image"), "Writes an (H, W, 3) array as an RGB float EXR");
}
