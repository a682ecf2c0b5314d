// tuile converge: error against render time, one curve per estimator strategy.
// Each strategy renders progressively (samples [0,1), [1,2), [2,4), ... so the total
// doubles) until its time budget is spent; after each pass the film's mean is compared
// with a reference (MSE, relMSE, efficiency = 1 / (relMSE T), Veach 1997 sec. 2.4; T is
// the summed render time only: no load, BVH build, metric or I/O time).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include "app/commands.h"

#include <CLI/CLI.hpp>
#include "accel/embree.h"
#include "scene/image_io.h"
#include "measure/metrics.h"
#include "scene/atomic_file.h"
#include "measure/plot.h"
#include "render/render.h"

namespace tuile {

namespace {

struct StrategyDef {
  const char* name;
  const char* flags;  // as documented
  void (*apply)(RenderFlags&);
};

const StrategyDef strategy_table[] = {
    {"light:area", "--strategy light --light-point area",
     [](RenderFlags& f) { f.strategy = "light", f.light_point = "area"; }},
    {"light:solid-angle", "--strategy light --light-point solid-angle",
     [](RenderFlags& f) { f.strategy = "light", f.light_point = "solid-angle"; }},
    {"light:uniform", "--strategy light --light-pick uniform",
     [](RenderFlags& f) { f.strategy = "light", f.light_pick = "uniform"; }},
    {"light:power", "--strategy light --light-pick power",
     [](RenderFlags& f) { f.strategy = "light", f.light_pick = "power"; }},
    {"light:all", "--strategy light --light-pick all",
     [](RenderFlags& f) { f.strategy = "light", f.light_pick = "all"; }},
    {"light:bvh", "--strategy light --light-pick bvh",
     [](RenderFlags& f) { f.strategy = "light", f.light_pick = "bvh"; }},
    {"bsdf", "--strategy bsdf", [](RenderFlags& f) { f.strategy = "bsdf"; }},
    {"mis:balance", "--strategy mis --mis-mode multi --heuristic balance",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "balance"; }},
    {"mis:power", "--strategy mis --mis-mode multi --heuristic power",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "power"; }},
    {"mis:cutoff", "--strategy mis --mis-mode multi --heuristic cutoff",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "cutoff"; }},
    {"mis:maximum", "--strategy mis --mis-mode multi --heuristic maximum",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "maximum"; }},
    {"mis:optimal", "--strategy mis --mis-mode multi --heuristic optimal (Kondapaneni et al. 2019: per-pixel weights)",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "optimal"; }},
    {"mis-one:balance", "--strategy mis --mis-mode one --heuristic balance",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "one", f.heuristic = "balance"; }},
    {"mis-one:power", "--strategy mis --mis-mode one --heuristic power",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "one", f.heuristic = "power"; }},
    {"mis:bvh", "--strategy mis --mis-mode multi --heuristic power --light-pick bvh",
     [](RenderFlags& f) { f.strategy = "mis", f.mis_mode = "multi", f.heuristic = "power", f.light_pick = "bvh"; }},
    {"ris", "--strategy ris --light-pick bvh (--ris-light, --ris-bsdf as given: 8 and 1 by default)",
     [](RenderFlags& f) { f.strategy = "ris", f.light_pick = "bvh"; }},
    {"ris:power", "--strategy ris --light-pick power",
     [](RenderFlags& f) { f.strategy = "ris", f.light_pick = "power"; }},
};

const StrategyDef& find_strategy(const std::string& name) {
  for (const StrategyDef& s : strategy_table)
    if (name == s.name) return s;
  std::string known;
  for (const StrategyDef& s : strategy_table) known += std::string(known.empty() ? "" : ", ") + s.name;
  throw std::invalid_argument("--strategies: unknown strategy '" + name + "' (known: " + known + ")");
}

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream in(s);
  while (std::getline(in, cur, ',')) {
    cur.erase(0, cur.find_first_not_of(" \t"));
    cur.erase(cur.find_last_not_of(" \t") + 1);
    if (!cur.empty()) out.push_back(cur);
  }
  return out;
}

std::string help_table() {
  std::string s = "Strategies (--strategies, comma-separated; default: all). The other render flags apply to all:\n";
  for (const StrategyDef& d : strategy_table) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-18s %s\n", d.name, d.flags);
    s += line;
  }
  s += "Without --reference, a reference is rendered first with mis:power and another seed\n"
       "(--reference-spp, default 64x the largest spp a calibration says fits the budget) and\n"
       "saved as <csv stem>-reference.exr when --csv is given.\n"
       "CSV: strategy,spp,seconds,mse,relmse,efficiency; seconds = cumulative render time only;\n"
       "relmse = mean((x-ref)^2/(ref^2+0.01)); efficiency = 1/(relmse*seconds).";
  return s;
}

std::string stem_of(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return path;
  return path.substr(0, dot);
}

// An output of the run, checked before it starts (its directory exists, it can be written
// there, it is not a directory), as render checks its image: a typo's directories are not
// created, and no output fails after the work.
void check_output(const std::string& path, const char* flag, const std::vector<std::string>& extensions) {
  try {
    check_output_path(path, extensions);
  } catch (const std::exception& e) {
    throw std::invalid_argument(std::string(flag) + " " + e.what());
  }
}

bool ends_with(const std::string& s, const std::string& e) {
  return s.size() >= e.size() && std::equal(e.rbegin(), e.rend(), s.rbegin());
}

}  // namespace

std::vector<std::string> converge_strategy_names() {
  std::vector<std::string> v;
  for (const StrategyDef& s : strategy_table) v.push_back(s.name);
  return v;
}

void add_converge_flags(CLI::App& app, ConvergeFlags& f) {
  app.add_option("--reference", f.reference, "reference EXR (same resolution); default: render one first");
  app.add_option("--strategies", f.strategies, "comma-separated strategies (see below); default: all");
  app.add_option("--budget", f.budget, "render seconds per strategy")->capture_default_str();
  app.add_option("--csv", f.csv, "CSV output: strategy,spp,seconds,mse,relmse,efficiency");
  app.add_option("--plot", f.plot, "plot of relMSE against time, drawn by matplotlib: FILE.png, FILE.svg or FILE.pdf");
  app.add_option("--spp-max", f.spp_max, "stop a strategy at this many samples per pixel (0 = only the budget)")
      ->capture_default_str();
  app.add_option("--reference-spp", f.reference_spp, "samples per pixel of the rendered reference (0 = automatic)")
      ->capture_default_str();
  app.footer(help_table());
}

ConvergeResult converge(const ConvergeFlags& f, Scene& scene, const Accel& accel, std::vector<float> reference,
                        bool print, const std::atomic<bool>* cancel,
                        const std::function<void(const std::vector<float>&)>& on_reference) {
  if (!(f.budget > 0) || !std::isfinite(f.budget)) throw std::invalid_argument("--budget must be a positive number of seconds");
  if (f.spp_max < 0) throw std::invalid_argument("--spp-max must be >= 0");
  if (f.reference_spp < 0) throw std::invalid_argument("--reference-spp must be >= 0");
  std::vector<const StrategyDef*> strategies;
  if (f.strategies.empty()) {
    for (const StrategyDef& s : strategy_table) strategies.push_back(&s);
  } else {
    for (const std::string& n : split_list(f.strategies)) strategies.push_back(&find_strategy(n));
    if (strategies.empty()) throw std::invalid_argument("--strategies: empty list");
  }
  const bool quiet = f.render.quiet;
  (void)resolve_options(f.render, scene);  // validates the shared flags, applies --res
  const int W = scene.camera.width, H = scene.camera.height;
  ConvergeResult out;
  out.width = W;
  out.height = H;
  auto check_cancel = [&] {
    if (cancel && cancel->load()) throw ConvergeCancelled();
  };

  // reference
  if (!reference.empty()) {
    if (reference.size() != static_cast<size_t>(W) * static_cast<size_t>(H) * 3)
      throw std::invalid_argument("the reference has " + std::to_string(reference.size() / 3) + " pixels but the render is " +
                                  std::to_string(W) + "x" + std::to_string(H) + " (use --res)");
    out.reference = std::move(reference);
  } else {
    RenderFlags rf = f.render;
    find_strategy("mis:power").apply(rf);
    rf.seed = f.render.seed ^ 0x9e3779b9u;  // independent of every strategy's samples
    RenderOptions opt = resolve_options(rf, scene);
    Renderer r(scene, accel, opt);
    r.set_cancel_flag(cancel);
    uint64_t ref_spp = static_cast<uint64_t>(f.reference_spp);
    double per_spp = 0;
    if (ref_spp == 0) {
      Film cal;
      cal.reset(W, H);
      const double t = r.render(cal, 0, 4).seconds;
      check_cancel();
      per_spp = std::max(t / 4, 1e-9);
      uint64_t reach = 1;
      while (reach * 2 <= 1u << 20 && 2.0 * static_cast<double>(reach) * per_spp <= f.budget) reach *= 2;
      if (f.spp_max > 0) reach = std::min<uint64_t>(reach, static_cast<uint64_t>(f.spp_max));
      ref_spp = std::clamp<uint64_t>(64 * reach, 256, uint64_t(1) << 24);
    }
    if (print) {
      std::printf("converge: no --reference given: rendering one with mis:power at %llu spp (seed %u)%s\n",
                  static_cast<unsigned long long>(ref_spp), rf.seed,
                  per_spp > 0 ? (", about " + std::to_string(static_cast<int>(std::ceil(per_spp * ref_spp))) + " s").c_str() : "");
      std::fflush(stdout);
    }
    Film film;
    film.reset(W, H);
    double t = 0;
    uint64_t done = 0;
    while (done < ref_spp) {
      const uint64_t end = std::min(ref_spp, std::max<uint64_t>(done * 2, 16));
      t += r.render(film, static_cast<uint32_t>(done), static_cast<uint32_t>(end)).seconds;
      check_cancel();
      done = end;
      if (!quiet) std::fprintf(stderr, "\rconverge: reference %llu / %llu spp, %.1f s", static_cast<unsigned long long>(done),
                               static_cast<unsigned long long>(ref_spp), t);
    }
    if (!quiet) std::fprintf(stderr, "\n");
    out.reference = film.mean();
    out.reference_spp = ref_spp;
    if (on_reference) on_reference(out.reference);
  }
  const std::vector<float>& ref = out.reference;

  // strategies
  const uint64_t spp_max = f.spp_max > 0 ? static_cast<uint64_t>(f.spp_max) : uint64_t(1) << 30;
  {
    // one untimed pass first, so thread start-up is not charged to the first strategy
    RenderFlags rf = f.render;
    strategies.front()->apply(rf);
    Renderer r(scene, accel, resolve_options(rf, scene));
    Film scratch;
    r.render(scratch, 0, 1);
  }
  if (print) std::printf("%-18s %8s %11s %12s %12s %12s\n", "strategy", "spp", "seconds", "mse", "relmse", "efficiency");
  for (const StrategyDef* s : strategies) {
    RenderFlags rf = f.render;
    s->apply(rf);
    RenderOptions opt = resolve_options(rf, scene);
    Renderer r(scene, accel, opt);
    r.set_cancel_flag(cancel);
    Film film;
    film.reset(W, H);
    double total = 0, last = 0;
    uint64_t begin = 0, end = 1;
    std::vector<float> img;
    for (;;) {
      last = r.render(film, static_cast<uint32_t>(begin), static_cast<uint32_t>(end)).seconds;
      check_cancel();
      total += last;
      img = film.mean();
      ConvergeRow row{s->name, end, total, mse(img, ref), relmse(img, ref), 0};
      row.efficiency = efficiency(row.relmse, row.seconds);
      out.rows.push_back(row);
      if (print) {
        std::printf("%-18s %8llu %11.5f %12.5g %12.5g %12.5g\n", s->name, static_cast<unsigned long long>(end), total,
                    row.mse, row.relmse, row.efficiency);
        std::fflush(stdout);
      }
      const uint64_t next = end * 2;
      // the next pass renders (next - end) samples; predict its time from this pass
      const double predicted = last * static_cast<double>(next - end) / static_cast<double>(end - begin);
      if (next > spp_max || next > (uint64_t(1) << 31) || total + predicted > f.budget) break;
      begin = end;
      end = next;
    }
    out.images.emplace_back(s->name, std::move(img));
  }
  return out;
}

int run_converge(const ConvergeFlags& f) {
  if (!f.plot.empty() && !ends_with(f.plot, ".svg") && !ends_with(f.plot, ".png") && !ends_with(f.plot, ".pdf"))
    throw std::invalid_argument("--plot '" + f.plot + "': expected a .png, .svg or .pdf file name");
  if (!f.csv.empty()) check_output(f.csv, "--csv", {".csv", ".txt"});
  if (!f.plot.empty()) check_output(f.plot, "--plot", {".png", ".svg", ".pdf"});
  Scene scene = load_scene(f.render.scene, LoadOptions{f.render.strict});
  (void)resolve_options(f.render, scene);  // validates the shared flags, applies --res
  for (const std::string& w : scene.warnings)
    if (!f.render.quiet) std::cerr << "tuile: warning: " << w << "\n";
  const int W = scene.camera.width, H = scene.camera.height;
  Accel accel(scene);
  std::vector<float> ref;
  if (!f.reference.empty()) {
    int rw = 0, rh = 0;
    ref = read_exr(f.reference, rw, rh);
    if (rw != W || rh != H)
      throw std::invalid_argument("--reference " + f.reference + " is " + std::to_string(rw) + "x" + std::to_string(rh) +
                                  " but the render is " + std::to_string(W) + "x" + std::to_string(H) + " (use --res)");
  }
  const ConvergeResult res = converge(f, scene, accel, std::move(ref), true, nullptr, [&](const std::vector<float>& r) {
    if (f.csv.empty()) return;
    const std::string path = stem_of(f.csv) + "-reference.exr";
    write_exr(path, W, H, r);
    std::printf("converge: reference saved as %s\n", path.c_str());
  });
  const std::vector<ConvergeRow>& rows = res.rows;
  std::vector<std::string> names;
  for (const auto& im : res.images) names.push_back(im.first);

  if (!f.csv.empty()) {
    std::ofstream csv(f.csv);
    if (!csv) throw std::runtime_error("cannot write " + f.csv);
    csv << "strategy,spp,seconds,mse,relmse,efficiency\n";
    char line[256];
    for (const ConvergeRow& r : rows) {
      std::snprintf(line, sizeof line, "%s,%llu,%.9g,%.9g,%.9g,%.9g\n", r.strategy.c_str(),
                    static_cast<unsigned long long>(r.spp), r.seconds, r.mse, r.relmse, r.efficiency);
      csv << line;
    }
    if (!csv) throw std::runtime_error("error writing " + f.csv);
  }

  // per strategy: series for the plot, final row and slope
  std::vector<PlotSeries> series;
  std::printf("\nper strategy (last row; slope = least-squares log-log slope of MSE against time, rows with spp >= 4; "
              "expect about -1):\n");
  std::printf("%-18s %8s %11s %12s %12s %12s %8s\n", "strategy", "spp", "seconds", "mse", "relmse", "efficiency", "slope");
  for (const std::string& name : names) {
    PlotSeries ps;
    ps.name = name;
    std::vector<double> t4, m4;
    const ConvergeRow* lastr = nullptr;
    for (const ConvergeRow& r : rows) {
      if (r.strategy != name) continue;
      ps.x.push_back(r.seconds);
      ps.y.push_back(r.relmse);
      if (r.spp >= 4) t4.push_back(r.seconds), m4.push_back(r.mse);
      lastr = &r;
    }
    const double slope = loglog_slope(t4, m4);
    if (lastr)
      std::printf("%-18s %8llu %11.5f %12.5g %12.5g %12.5g %8.3f\n", name.c_str(), static_cast<unsigned long long>(lastr->spp),
                  lastr->seconds, lastr->mse, lastr->relmse, lastr->efficiency, slope);
    series.push_back(std::move(ps));
  }
  // the winner per time budget: lowest relMSE interpolated (log-log) at t = 2^k seconds
  double tmin = HUGE_VAL, tmax = 0;
  for (const PlotSeries& ps : series)
    if (!ps.x.empty()) tmin = std::min(tmin, ps.x.front()), tmax = std::max(tmax, ps.x.back());
  if (tmax > 0) {
    std::printf("\nthe winner per time budget (relMSE interpolated in log-log at each power of two seconds):\n");
    std::printf("%12s  %-18s %12s  %-18s %12s\n", "budget (s)", "winner", "relmse", "runner-up", "relmse");
    for (int k = static_cast<int>(std::ceil(std::log2(tmin))); std::ldexp(1.0, k) <= tmax; ++k) {
      const double t = std::ldexp(1.0, k);
      std::vector<std::pair<double, std::string>> at;
      for (const PlotSeries& ps : series) {
        const double v = loglog_interpolate(ps.x, ps.y, t);
        if (std::isfinite(v)) at.emplace_back(v, ps.name);
      }
      if (at.empty()) continue;
      std::sort(at.begin(), at.end());
      char budget[32];
      if (k < 0) std::snprintf(budget, sizeof budget, "2^%d", k);
      else std::snprintf(budget, sizeof budget, "%g", t);
      if (at.size() > 1)
        std::printf("%12s  %-18s %12.5g  %-18s %12.5g\n", budget, at[0].second.c_str(), at[0].first,
                    at[1].second.c_str(), at[1].first);
      else
        std::printf("%12s  %-18s %12.5g\n", budget, at[0].second.c_str(), at[0].first);
    }
  }

  if (!f.csv.empty()) std::printf("converge: %zu rows written to %s\n", rows.size(), f.csv.c_str());
  if (!f.plot.empty()) {
    Plot p;
    p.output = f.plot;
    p.title = "relMSE against render time: " + scene.source.substr(scene.source.find_last_of('/') + 1);
    p.xlabel = "render time (s)";
    p.ylabel = "relMSE";
    p.series = std::move(series);
    p.guide_slope = -1;
    p.guide_label = "1/t";
    draw_with_matplotlib({p}, {});
    std::printf("converge: plot written to %s (matplotlib)\n", f.plot.c_str());
  }
  return 0;
}

}  // namespace tuile
