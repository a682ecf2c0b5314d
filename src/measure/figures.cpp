// tuile figures: the course's experiments as labelled PNG contact sheets, drawn by
// matplotlib (measure/plot.h: tuile renders, python/tuile/plot.py draws).
//   a-noise.png              noise at 1, 4, 16, 64, 256, 1024 spp (noise-room)
//   b-points-per-source.png  1 / 16 / 64 points per source, every source, 1 spp (noise-room)
//   c-light-pdfs.png         p = 1/S 1/A, p = 1/sum A, solid angle (two-panels)
//   d-mis.png                light alone, BSDF alone, MIS balance and power, BSDF weight (near-far)
//   e-warmup.png/.svg        RMS error of the mean of N random values against N
//   f-veach-plates.png       the same five panels on Veach's glossy plates (veach-plates)
//   g-optimal-mis.png        MIS balance, power and optimal at equal samples and at equal
//                            time, and optimal MIS's per-pixel alphas (two-panels, veach-plates)
// Scenes come from scenes/course/ of the source tree (TUILE_SOURCE_DIR); when a file is
// missing the built-in two-panels scene stands in and the sheet says so.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include "app/commands.h"

#include <CLI/CLI.hpp>
#include "accel/embree.h"
#include "scene/image_io.h"
#include "measure/plot.h"
#include "render/render.h"
#include "wave/optimal_mis.h"

#ifndef TUILE_SOURCE_DIR
#define TUILE_SOURCE_DIR "."
#endif

namespace tuile {

namespace {

using Panel = SheetPanel;

// Linear RGB, shown as sRGB.
Panel srgb_panel(std::string label, int w, int h, std::vector<float> rgb) {
  return Panel{std::move(label), "srgb", w, h, 3, std::move(rgb)};
}

// A [0, 1] quantity (an MIS weight) shown linearly as grey.
Panel grey_panel(std::string label, int w, int h, std::vector<float> y) {
  return Panel{std::move(label), "grey", w, h, 1, std::move(y)};
}

// A signed quantity (an optimal MIS alpha, in radiance units): its luminance, positive as
// sRGB grey, negative in red.
Panel signed_panel(std::string label, int w, int h, std::vector<float> rgb) {
  return Panel{std::move(label), "signed", w, h, 3, std::move(rgb)};
}

// The sheets and plots of the run, drawn together at the end (one start of matplotlib).
struct Figures {
  std::vector<Sheet> sheets;
  std::vector<Plot> plots;
  void sheet(const std::string& path, const std::string& title, std::vector<Panel> panels, int columns) {
    sheets.push_back(Sheet{path, title, columns, std::move(panels)});
  }
};

std::string course_scene(const std::string& name, std::string& note) {
  const std::string path = std::string(TUILE_SOURCE_DIR) + "/scenes/course/" + name;
  if (std::filesystem::exists(path)) return path;
  note = " (" + name + " not found: built-in two-panels)";
  return "built-in:two-panels";
}

// One scene and its BVH, rendered under several flag sets.
struct SceneSetup {
  Scene scene;
  std::unique_ptr<Accel> accel;
  int threads = 0;
  std::string res;
  SceneSetup(const std::string& path, int w, int h, int threads_) : scene(load_scene(path)), threads(threads_) {
    res = std::to_string(w) + "x" + std::to_string(h);
    accel = std::make_unique<Accel>(scene);
  }
  RenderFlags flags() const {
    RenderFlags f;
    f.scene = scene.source;
    f.res = res;
    f.threads = threads;
    f.quiet = true;
    return f;
  }
  // Renders samples [0, spp) under the flags into a fresh film.
  Film render(const RenderFlags& f, uint32_t spp, bool mis_weight = false) {
    RenderOptions o = resolve_options(f, scene);
    o.aov_mis_weight = mis_weight;
    Renderer r(scene, *accel, o);
    Film film;
    film.reset(scene.camera.width, scene.camera.height);
    r.render(film, 0, spp);
    return film;
  }
};

// The MIS panels of sheets (d) and (f) on one course scene, at `spp` samples per pixel:
// light sampling alone, BSDF sampling alone (one sample each), MIS with one light and one
// BSDF sample under the balance and power heuristics, and the balance heuristic's weight of
// the BSDF technique per pixel as grey.
void mis_sheet(Figures& figs, const std::string& png, const std::string& title, const std::string& scene_file, int w,
               int h, uint32_t spp, int threads) {
  std::string note;
  const std::string path = course_scene(scene_file, note);
  SceneSetup st(path, w, h, threads);
  std::vector<Panel> panels;
  RenderFlags rf = st.flags();
  rf.strategy = "light";
  Film film = st.render(rf, spp);
  panels.push_back(srgb_panel("1: light alone", film.width, film.height, film.mean()));
  rf.strategy = "bsdf";
  film = st.render(rf, spp);
  panels.push_back(srgb_panel("2: BSDF alone", film.width, film.height, film.mean()));
  rf.strategy = "mis";
  rf.mis_mode = "multi";
  rf.heuristic = "balance";
  film = st.render(rf, spp, true);
  panels.push_back(srgb_panel("MIS balance", film.width, film.height, film.mean()));
  const Panel weight = grey_panel("weight of 2 (balance)", film.width, film.height, film.mis_weight());
  rf.heuristic = "power";
  film = st.render(rf, spp);
  panels.push_back(srgb_panel("MIS power", film.width, film.height, film.mean()));
  panels.push_back(weight);
  figs.sheet(png, title + ", " + std::to_string(spp) + " spp" + note, std::move(panels), 3);
}

// (g) optimal MIS (Kondapaneni et al. 2019) against the balance and power heuristics on
// one course scene: the three at `spp` samples per pixel; the three at the time the slowest
// of them took (each renders doubling passes and stops before the next would pass it); and
// the per-pixel alphas of the light and BSDF techniques solved from the optimal render's
// moments (wave/optimal_mis.h).
void optimal_rows(SceneSetup& st, const std::string& name, uint32_t spp, std::vector<Panel>& panels) {
  const char* hs[3] = {"balance", "power", "optimal"};
  auto options = [&](int k) {
    RenderFlags rf = st.flags();
    rf.strategy = "mis";
    rf.mis_mode = "multi";
    rf.heuristic = hs[k];
    return resolve_options(rf, st.scene);
  };
  double seconds[3] = {0, 0, 0};
  Film optimal;
  for (int k = 0; k < 3; ++k) {
    Renderer r(st.scene, *st.accel, options(k));
    Film film;
    film.reset(st.scene.camera.width, st.scene.camera.height);
    seconds[k] = r.render(film, 0, spp).seconds;
    panels.push_back(srgb_panel(name + " " + hs[k] + ", " + std::to_string(spp) + " spp", film.width, film.height, film.mean()));
    if (k == 2) optimal = film;
  }
  const double budget = std::max({seconds[0], seconds[1], seconds[2]});
  for (int k = 0; k < 3; ++k) {
    Renderer r(st.scene, *st.accel, options(k));
    Film film;
    film.reset(st.scene.camera.width, st.scene.camera.height);
    double t = 0;
    uint32_t done = 0;
    for (uint32_t next = std::max<uint32_t>(1, spp / 8);; next = done * 2) {
      t += r.render(film, done, next).seconds;
      done = next;
      if (2 * t > budget * 1.05 || done >= (1u << 20)) break;  // the next pass doubles the time
    }
    char label[96];
    std::snprintf(label, sizeof(label), " %s, equal time (%u spp)", hs[k], done);
    panels.push_back(srgb_panel(name + label, film.width, film.height, film.mean()));
  }
  const size_t n = static_cast<size_t>(optimal.width) * static_cast<size_t>(optimal.height);
  std::vector<float> al(3 * n), ab(3 * n);
  for (size_t i = 0; i < n; ++i) solve_optimal_alpha(&optimal.optimal[9 * i], &al[3 * i], &ab[3 * i]);
  panels.push_back(signed_panel(name + " alpha light (red < 0)", optimal.width, optimal.height, al));
  panels.push_back(signed_panel(name + " alpha BSDF (red < 0)", optimal.width, optimal.height, ab));
}

// (e) the error of the mean of N values against N, over many trials
struct SplitMix {
  uint64_t s;
  uint64_t next() {
    uint64_t z = (s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }  // [0, 1)
};

void warmup_plot(Figures& figs, const std::string& out, bool quick) {
  const int max_log2 = quick ? 10 : 14, trials = quick ? 200 : 2000;
  Plot p;
  p.title = "Error of the mean of N random values";
  p.xlabel = "N (values averaged)";
  p.ylabel = "RMS error";
  p.guide_slope = -0.5;
  p.guide_label = "1/sqrt(N)";
  const char* names[3] = {"U[-1,1]", "U[-10,10]", "U[-1,1], 1% in U[-10,10]"};
  for (int kind = 0; kind < 3; ++kind) {
    PlotSeries s;
    s.name = names[kind];
    SplitMix rng{0x1234567ull + static_cast<uint64_t>(kind) * 0x1000193ull};
    for (int k = 0; k <= max_log2; ++k) {
      const int n = 1 << k;
      double sq = 0;
      for (int t = 0; t < trials; ++t) {
        double sum = 0;
        for (int i = 0; i < n; ++i) {
          double half = kind == 1 ? 10 : 1;
          if (kind == 2 && rng.uniform() < 0.01) half = 10;  // an accident
          sum += (2 * rng.uniform() - 1) * half;
        }
        const double err = sum / n;  // the true mean is 0
        sq += err * err;
      }
      s.x.push_back(n);
      s.y.push_back(std::sqrt(sq / trials));
    }
    p.series.push_back(std::move(s));
  }
  p.output = out + "/e-warmup.png";
  figs.plots.push_back(p);
  p.output = out + "/e-warmup.svg";
  figs.plots.push_back(p);
}

}  // namespace

void add_figures_flags(CLI::App& app, FiguresFlags& f) {
  app.add_option("--out", f.out, "output folder")->capture_default_str();
  app.add_option("--threads", f.threads, "worker threads (0 = all cores)");
  app.add_flag("--quick", f.quick, "small images and sample counts");
  app.footer(
      "Writes a-noise.png (1..1024 spp), b-points-per-source.png (1/16/64 points per source, 1 spp),\n"
      "c-light-pdfs.png (p = 1/S 1/A, p = 1/sum A, solid angle), d-mis.png (light, BSDF, MIS balance/power,\n"
      "BSDF weight as grey), e-warmup.png/.svg (error of the mean of N values against N) and\n"
      "f-veach-plates.png (d's panels on Veach's plates: four lights of equal power on four plates),\n"
      "g-optimal-mis.png (MIS balance, power and optimal at equal samples and equal time, optimal's alphas).");
}

int run_figures(const FiguresFlags& f) {
  if (f.threads < 0 || f.threads > 1024) throw std::invalid_argument("--threads must be in 0..1024");
  {  // the output folder (made if missing), before any work
    std::error_code ec;
    if (std::filesystem::exists(f.out, ec) && !std::filesystem::is_directory(f.out, ec))
      throw std::invalid_argument("--out " + f.out + ": exists and is not a folder");
    std::filesystem::create_directories(f.out, ec);
    if (ec) throw std::invalid_argument("--out " + f.out + ": cannot make the folder: " + ec.message());
  }
  const bool q = f.quick;
  Figures figs;

  // (a) noise against samples per pixel: one progressive render, snapshots at 4^k
  {
    std::string note;
    const std::string path = course_scene("noise-room.pbrt", note);
    SceneSetup st(path, q ? 40 : 256, q ? 40 : 256, f.threads);
    RenderFlags rf = st.flags();
    RenderOptions o = resolve_options(rf, st.scene);
    Renderer r(st.scene, *st.accel, o);
    Film film;
    film.reset(st.scene.camera.width, st.scene.camera.height);
    std::vector<Panel> panels;
    uint32_t done = 0;
    for (uint32_t spp : {1u, 4u, 16u, 64u, 256u, 1024u}) {
      r.render(film, done, spp);
      done = spp;
      panels.push_back(srgb_panel(std::to_string(spp) + " spp", film.width, film.height, film.mean()));
    }
    figs.sheet(f.out + "/a-noise.png", "(a) Noise against samples per pixel, MIS power heuristic" + note, std::move(panels), 3);
  }

  // (b) N points on every source at 1 spp
  {
    std::string note;
    const std::string path = course_scene("noise-room.pbrt", note);
    SceneSetup st(path, q ? 40 : 256, q ? 40 : 256, f.threads);
    std::vector<Panel> panels;
    for (int n : {1, 16, 64}) {
      RenderFlags rf = st.flags();
      rf.strategy = "light";
      rf.light_pick = "all";
      rf.light_samples = n;
      const Film film = st.render(rf, 1);
      panels.push_back(srgb_panel(std::to_string(n) + (n == 1 ? " point" : " points") + " per source",
                                  film.width, film.height, film.mean()));
    }
    figs.sheet(f.out + "/b-points-per-source.png", "(b) Points per source, every source, 1 spp" + note, std::move(panels), 3);
  }

  // (c) how the light point is chosen: p = 1/S 1/A, p = 1/sum A, solid angle
  {
    std::string note;
    const std::string path = course_scene("two-panels.pbrt", note);
    SceneSetup st(path, q ? 72 : 450, q ? 24 : 150, f.threads);
    const uint32_t spp = q ? 4 : 16;
    struct Case {
      const char* label;
      const char* pick;
      const char* point;
    };
    const Case cases[] = {{"p = 1/S * 1/A", "uniform", "area"},
                          {"p = 1/sum A", "area", "area"},
                          {"solid angle", "area", "solid-angle"}};
    std::vector<Panel> panels;
    for (const Case& c : cases) {
      RenderFlags rf = st.flags();
      rf.strategy = "light";
      rf.light_pick = c.pick;
      rf.light_point = c.point;
      const Film film = st.render(rf, spp);
      panels.push_back(srgb_panel(c.label, film.width, film.height, film.mean()));
    }
    figs.sheet(f.out + "/c-light-pdfs.png", "(c) Light sampling pdfs, " + std::to_string(spp) + " spp" + note,
               std::move(panels), 3);
  }

  // (d) MIS on near-far
  mis_sheet(figs, f.out + "/d-mis.png", "(d) Multiple importance sampling", "near-far.pbrt", q ? 40 : 320, q ? 30 : 240,
            q ? 4 : 16, f.threads);

  // (e) the 1D warm-up
  warmup_plot(figs, f.out, q);

  // (f) Veach's plates: four lights of equal power, radii x3 apart, on four plates of growing roughness
  mis_sheet(figs, f.out + "/f-veach-plates.png", "(f) Veach's plates, MIS", "veach-plates.pbrt", q ? 64 : 384,
            q ? 48 : 288, q ? 2 : 8, f.threads);

  // (g) optimal MIS weights against the heuristics, on two-panels and the plates
  {
    std::vector<Panel> panels;
    std::string notes;
    for (const char* file : {"two-panels.pbrt", "veach-plates.pbrt"}) {
      std::string note;
      const std::string path = course_scene(file, note);
      const bool plates = std::string(file) == "veach-plates.pbrt";
      SceneSetup st(path, plates ? (q ? 64 : 256) : (q ? 72 : 300), plates ? (q ? 48 : 192) : (q ? 24 : 100), f.threads);
      optimal_rows(st, plates ? "plates" : "panels", q ? 2 : 64, panels);
      notes += note;
    }
    figs.sheet(f.out + "/g-optimal-mis.png",
               "(g) Optimal MIS weights (Kondapaneni et al. 2019) against balance and power" + notes, std::move(panels), 4);
  }
  // drawn by matplotlib (python/tuile/plot.py), all in one run
  draw_with_matplotlib(figs.plots, figs.sheets);
  for (const Sheet& sh : figs.sheets) std::printf("figures: %s\n", sh.output.c_str());
  for (const Plot& p : figs.plots) std::printf("figures: %s\n", p.output.c_str());
  return 0;
}

}  // namespace tuile
