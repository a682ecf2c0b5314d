// The subcommands render, info, bench and profile (converge, figures and diff live in
// src/measure).
#include "app/commands.h"

#include <CLI/CLI.hpp>

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <iterator>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <iostream>

#include "accel/embree.h"
#include "app/prepare.h"
#include "scene/atomic_file.h"
#include "scene/image_io.h"
#include "scene/sky_map.h"
#include "render/filter_table.h"
#include "render/light_paths.h"
#include "render/render.h"
#include "measure/roofline.h"

namespace tuile {

void add_bench_flags(CLI::App& app, BenchFlags& f) {
  app.add_option("--repeat", f.repeat, "timed renders")->capture_default_str();
  app.add_option("--warmup", f.warmup, "untimed renders first")->capture_default_str();
  app.add_option("--json", f.json, "write the figures as JSON");
}
void add_profile_flags(CLI::App& app, ProfileFlags& f) {
  app.add_option("--trace", f.trace, "Chrome trace-event JSON");
  app.add_option("--json", f.json, "write the figures as JSON");
  app.add_flag("--roofline", f.roofline, "compare with Embree alone on the same rays");
}
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string with_extension(const std::string& path, const char* ext) {
  return std::filesystem::path(path).replace_extension(ext).string();
}

Prepared prepare(const RenderFlags& f) {
  Prepared p;
  EmbreeOptions eo;
  if (f.bvh == "fast") eo.compact = 0;
  else if (f.bvh == "compact") eo.compact = 1;
  else if (f.bvh != "auto") throw std::invalid_argument("--bvh '" + f.bvh + "': expected auto, fast or compact");
  const auto t0 = std::chrono::steady_clock::now();
  p.scene = load_scene(f.scene, LoadOptions{f.strict});
  p.opt = resolve_options(f, p.scene);
  p.load_seconds = seconds_since(t0);
  const auto t1 = std::chrono::steady_clock::now();
  p.accel = std::make_unique<Accel>(p.scene, eo);
  p.bvh_seconds = seconds_since(t1);
  return p;
}

static void appendf(std::string& out, const char* fmt, ...) {
  char buf[1024];
  va_list ap;
  va_start(ap, fmt);
  const int n = std::vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  if (n < 0) return;
  if (static_cast<size_t>(n) < sizeof buf) {
    out.append(buf, static_cast<size_t>(n));
    return;
  }
  std::string big(static_cast<size_t>(n) + 1, '\0');
  va_start(ap, fmt);
  std::vsnprintf(big.data(), big.size(), fmt, ap);
  va_end(ap);
  big.resize(static_cast<size_t>(n));
  out += big;
}

std::string info_text(const Prepared& p) {
  std::string out;
  auto say = [&out](const char* fmt, auto... args) { appendf(out, fmt, args...); };
  const Scene& scene = p.scene;
  const RenderOptions& opt = p.opt;
  const Accel& accel = *p.accel;
  const double load = p.load_seconds, bvh = p.bvh_seconds;
  size_t area = 0, delta = 0, skies = 0;
  for (const Light& l : scene.lights) (is_delta(l.type) ? delta : is_sky(l.type) ? skies : area)++;
  say("scene: %s\n", scene.source.c_str());
  say("resolution: %dx%d\n", scene.camera.width, scene.camera.height);
  say("triangles: %zu\nspheres: %zu\nmeshes: %zu\nmaterials: %zu\ntextures: %zu\n", scene.triangle_count(),
              scene.spheres.size(), scene.meshes.size(), scene.materials.size(), scene.textures.size());
  if (!scene.instances.empty())
    say("instances: %zu of %zu object(s), %zu triangles rendered\n", scene.instances.size(), scene.objects.size(),
        scene.instanced_triangle_count());
  if (!scene.curves.empty()) {
    size_t segments = 0, kinds[3] = {0, 0, 0};
    for (const Curves& c : scene.curves) {
      segments += c.segment_count();
      ++kinds[static_cast<int>(c.type)];
    }
    say("curves: %zu (%zu cubic Bezier segments; flat %zu, ribbon %zu, cylinder %zu)\n", scene.curves.size(), segments,
        kinds[0], kinds[1], kinds[2]);
  }
  say("lights: %zu (area sources %zu, delta %zu, skies %zu)\n", scene.lights.size(), area, delta, skies);
  if (!scene.media.empty()) {
    say("media: %zu%s\n", scene.media.size(),
        scene.camera_medium >= 0 ? (", the camera is in \"" + scene.media[size_t(scene.camera_medium)].name + "\"").c_str() : "");
    for (const Medium& m : scene.media) {
      if (m.supported)
        say("  %s (%s, %s): sigma_a (%.4g, %.4g, %.4g), sigma_s (%.4g, %.4g, %.4g)%s%s, g %.3g, Le (%.4g, %.4g, %.4g); bounded by %d shape(s)\n",
            m.name.c_str(), m.type.c_str(), m.where.c_str(), m.sigma_a.r, m.sigma_a.g, m.sigma_a.b, m.sigma_s.r, m.sigma_s.g,
            m.sigma_s.b, m.preset.empty() ? "" : ", preset ", m.preset.c_str(), m.g, m.Le.r, m.Le.g, m.Le.b, m.bounding_shapes);
      else
        say("  %s (%s, %s): not supported; bounded by %d shape(s)\n", m.name.c_str(), m.type.c_str(), m.where.c_str(),
            m.bounding_shapes);
    }
  }
  // each sky: its map (file, size, power) and how its light samples are drawn
  {
    const Estimator& e = opt.est;
    const bool compensated = (e.strategy == Strategy::mis && e.bsdf_samples > 0) || (e.strategy == Strategy::ris && e.ris_bsdf > 0);
    for (const Light& l : scene.lights) {
      if (!is_sky(l.type)) continue;
      if (l.sky_map < 0) {
        say("sky: constant, radiance (%g, %g, %g), power %.4g; sampled %s\n", l.radiance.r, l.radiance.g, l.radiance.b,
                    l.power,
                    compensated ? "by the BSDF technique alone (MIS: a constant sky's compensated density is 0)"
                                : "uniformly over the sphere");
        continue;
      }
      const SkyMap& m = scene.sky_maps[static_cast<size_t>(l.sky_map)];
      say("sky: map %s, %dx%d texels (equal-area octahedral, nearest texel), scale %g, mean texel (%.4g, %.4g, %.4g), "
                  "power %.4g; sampled by a piecewise-constant 2-D distribution over its texels%s\n",
                  m.file.c_str(), m.res, m.res, l.radiance.r, m.mean[0], m.mean[1], m.mean[2], l.power,
                  compensated ? ", MIS-compensated (max(value - mean, 0))" : " (their mean channel)");
    }
  }
  say("features:");
  for (size_t i = 0; i < std::size(scene_feature_names); ++i)
    if (scene.features & (1u << i)) say(" %s", scene_feature_names[i]);
  // the kinds of surface the geometry has (through mixes too), and how many shapes use each
  {
    size_t per_kind[material_kind_count] = {};
    size_t mixes = 0;
    auto count = [&](int m) {
      if (m < 0 || static_cast<size_t>(m) >= scene.materials.size()) {
        ++per_kind[0];  // the default grey
        return;
      }
      const Material& mt = scene.materials[static_cast<size_t>(m)];
      if (mt.mix[0] >= 0) {
        ++mixes;
        for (int i : mt.mix) ++per_kind[static_cast<int>(scene.materials[static_cast<size_t>(i)].kind)];
      } else {
        ++per_kind[static_cast<int>(mt.kind)];
      }
    };
    for (const Mesh& m : scene.meshes) count(m.material);
    for (const Sphere& sp : scene.spheres) count(sp.material);
    for (const Curves& c : scene.curves) count(c.material);
    say("\nsurfaces:");
    for (int k = 0; k < material_kind_count; ++k)
      if (per_kind[k]) say(" %s (%zu)", material_kind_names[k], per_kind[k]);
    if (mixes) say(", %zu through mix", mixes);
  }
  say("\nestimator: %s\n", describe(opt.est).c_str());
  say("pixel filter: %s\n", describe(opt.filter).c_str());
  {
    Renderer r(scene, accel, opt);
    std::string why;
    const std::string name = r.pipeline_name(&why);
    if (opt.est.bdpt) {  // no tile pipeline, no picker of the path tracer's
      say("pipeline: bdpt (bidirectional path tracing, no tile pipeline: a camera and a light subpath per pixel and "
          "sample, every join weighted by the balance heuristic)\n");
      say("bdpt: %s\n", r.bdpt_sources().c_str());
      say("paths: up to %d vertices a path, Russian roulette after vertex %d below throughput %g on both subpaths; every "
          "ray against the whole scene\n",
          opt.est.max_depth, opt.est.rr_depth + 1, static_cast<double>(opt.est.rr_threshold));
    } else {
      say("pipeline: %s (%s)\n", name.c_str(), why.c_str());
      // which picker chooses the source of each light sample
      if (const LightBvh* b = r.light_bvh()) {
        const LightBvhView bv = b->view();
        const size_t in_tree = static_cast<size_t>(bv.nodes + 1) / 2, distant = static_cast<size_t>(bv.distant);
        say("light picker: bvh (a light BVH over %zu sources, depth %d, %.1f bytes per source, built in %.3f s; "
                    "%zu distant sources picked beside it)\n",
                    in_tree, b->depth,
                    static_cast<double>(b->bytes()) / static_cast<double>(std::max<size_t>(1, scene.lights.size())),
                    r.light_bvh_seconds(), distant);
      } else if (opt.est.pick == LightPick::all) {
        say("light picker: all (every source takes the light samples)\n");
      } else {
        static const char* names[] = {"all", "uniform", "area", "power", "bvh"};
        say("light picker: %s (an alias table: the same probabilities at every shading point)%s\n",
                    names[static_cast<int>(opt.est.pick)],
                    opt.est.pick == LightPick::bvh ? "; bvh needs two sources or more" : "");
        // the sources at infinity's shares, where they share the picks (under MIS a sky weighs
        // the compensated part of its map: light/kinds/infinite.h)
        double at_infinity = 0;
        size_t others = 0;
        std::string shares;
        for (size_t i = 0; i < scene.lights.size(); ++i) {
          const LightKind k = scene.lights[i].type;
          if (k != LightKind::distant && !is_sky(k)) {
            ++others;
            continue;
          }
          const float p = r.light_pick_probability(static_cast<int>(i));
          at_infinity += p;
          char buf[64];
          std::snprintf(buf, sizeof buf, "%s%s %.3g", shares.empty() ? "" : ", ", is_sky(k) ? "sky" : "distant", p);
          shares += buf;
        }
        if (!shares.empty() && scene.lights.size() > 1) {
          say("  picks of the sources at infinity: %s", shares.c_str());
          if (others > 0) say("; the other %zu source(s) %.3g", others, std::max(0.0, 1.0 - at_infinity));
          say("\n");
        }
      }
      // (under a sky the rays that find no emitter take an occlusion ray to infinity; in a
      // medium the rays see the whole scene)
      const bool emitters = r.bounce_against_emitters();
      const std::string per_ray = std::string(emitters && (scene.features & feat_sky) ? ", to infinity where they find none" : "") +
                                  (emitters && (scene.features & feat_media) ? "; those that start in a medium against the whole scene" : "");
      if (opt.est.max_depth > 1)
        say("paths: up to %d vertices, Russian roulette after vertex %d below throughput %g (pbrt-v4's rule: 1); "
                    "bounce rays against the whole scene, %s%s\n",
                    opt.est.max_depth, opt.est.rr_depth + 1, static_cast<double>(opt.est.rr_threshold),
                    emitters ? "those of the paths that end at a vertex (Russian roulette) and the last vertex's against the "
                               "emitters, then occlusion rays"
                             : "the last vertex's against the whole scene",
                    per_ray.c_str());
      else
        say("bounce rays: against the %s%s\n", emitters ? "emitters, then occlusion rays" : "whole scene", per_ray.c_str());
    }
    // --light-paths: what runs, and the figure auto's glossy choice rests on
    if (opt.est.light_paths)
      say("light paths: %s, %s%s\n", opt.est.light_paths_glossy ? "glossy" : "on",
          r.has_light_paths() ? "a light path per pixel and sample after the camera's, from "
                              : "inactive (nothing the light tracer could trace and join to the camera)",
          r.light_paths_sources().c_str());
    const double glints = area_glint_share(scene);
    if (glints > 0)
      say("glints: %.3g of the area sources' power falls on near-specular surfaces from a source that looks small "
          "from them (--light-paths auto takes glossy from 0.01)\n",
          glints);
    const double caustics = area_caustic_share(scene);
    if (caustics > 0)
      say("caustics: %.3g of the area sources' power falls on smooth glass or mirrors from a source that looks small "
          "from them (--light-paths auto takes on from 0.003)\n",
          caustics);
  }
  for (const std::string& w : scene.warnings) say("approximation: %s\n", w.c_str());
  for (const std::string& w : scene.notes) say("note: %s\n", w.c_str());
  say("load: %.3f s\nbvh build: %.3f s (%s layout)\n", load, bvh, accel.compact() ? "compact" : "fast");
  return out;
}

int run_info(const RenderFlags& f) {
  std::fputs(info_text(prepare(f)).c_str(), stdout);
  return 0;
}

namespace {

size_t peak_memory_bytes() {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<size_t>(ru.ru_maxrss) * 1024;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Writes the whole file or throws naming it.
void write_text_file(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << text;
  out.flush();
  if (!out) throw std::runtime_error(path + ": error writing");
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    if (ch == '"' || ch == '\\') o += '\\';
    if (static_cast<unsigned char>(ch) < 0x20) continue;
    o += ch;
  }
  return o;
}

}  // namespace

int run_bench(const BenchFlags& f, std::string* json) {
  std::string text;
  auto say = [&text](const char* fmt, auto... args) { appendf(text, fmt, args...); };
  if (f.repeat < 1 || f.repeat > 1000) throw std::invalid_argument("--repeat must be in 1..1000");
  if (f.warmup < 0 || f.warmup > 1000) throw std::invalid_argument("--warmup must be in 0..1000");
  if (!f.json.empty()) check_output_path(f.json, {".json"});  // before the work, not after it
  const auto start = std::chrono::steady_clock::now();
  Prepared p = prepare(f.render);
  Renderer renderer(p.scene, *p.accel, p.opt);
  const double first_pixel = seconds_since(start);  // load + BVH + light tables
  const uint32_t spp = p.opt.est.spp;
  std::vector<double> sps, cam, sh, bo, vps;
  RenderStats last;
  for (int r = 0; r < f.warmup + f.repeat; ++r) {
    Film film;
    film.reset(p.scene.camera.width, p.scene.camera.height);
    const RenderStats st = renderer.render(film, 0, spp);
    if (r < f.warmup) continue;
    sps.push_back(static_cast<double>(st.samples) / st.seconds);
    cam.push_back(static_cast<double>(st.rays_camera) / st.seconds);
    sh.push_back(static_cast<double>(st.rays_shadow) / st.seconds);
    bo.push_back(static_cast<double>(st.rays_bounce) / st.seconds);
    vps.push_back(static_cast<double>(st.samples + st.path_vertices) / st.seconds);
    last = st;
  }
  const double med = median(sps);
  const double mn = *std::min_element(sps.begin(), sps.end()), mx = *std::max_element(sps.begin(), sps.end());
  const int threads = p.opt.threads > 0 ? p.opt.threads : static_cast<int>(std::thread::hardware_concurrency());
  say("scene: %s (%zu triangles, %zu lights)\n", p.scene.source.c_str(), p.scene.triangle_count(),
              p.scene.lights.size());
  if (!p.scene.instances.empty())
    say("instances: %zu of %zu object(s): %zu triangles rendered for the %zu stored\n", p.scene.instances.size(),
        p.scene.objects.size(), p.scene.instanced_triangle_count(), p.scene.triangle_count());
  say("pipeline: %s, bounce rays against the %s\nestimator: %s\n", last.pipeline.c_str(),
              last.bounce_against_emitters ? "emitters" : "scene", describe(p.opt.est).c_str());
  say("resolution %dx%d, %u spp, %d thread(s), %d runs after %d warm-up\n", p.scene.camera.width,
              p.scene.camera.height, spp, threads, f.repeat, f.warmup);
  say("samples/s: median %.4g  min %.4g  max %.4g\n", med, mn, mx);
  const double vertices = 1.0 + static_cast<double>(last.path_vertices) / static_cast<double>(std::max<uint64_t>(1, last.samples));
  if (p.opt.est.max_depth > 1)  // one path per sample
    say("paths/s: median %.4g (max depth %d); %.3g vertices per path, %.4g vertices/s\n", med, p.opt.est.max_depth,
                vertices, median(vps));
  say("rays/s (median): camera %.4g  shadow %.4g  bounce %.4g\n", median(cam), median(sh), median(bo));
  say("time to first pixel: %.3f s (load %.3f s, BVH %.3f s)\n", first_pixel, p.load_seconds, p.bvh_seconds);
  const double per_triangle =
      static_cast<double>(peak_memory_bytes()) / static_cast<double>(std::max<size_t>(1, p.scene.triangle_count()));
  say("peak memory: %.1f MiB (%.1f bytes per stored triangle)\n", static_cast<double>(peak_memory_bytes()) / (1024.0 * 1024.0),
      per_triangle);
  {  // where the bytes go: the scene's shapes, Embree's BVHs (and at peak their builds)
    size_t shapes = 0;
    for (const Mesh& m : p.scene.meshes)
      shapes += 4 * (m.positions.capacity() + m.uvs.capacity() + m.normals.capacity() + m.indices.capacity() +
                     m.prim_light.capacity());
    for (const Curves& c : p.scene.curves) shapes += 4 * (c.points.capacity() + c.normals.capacity());
    const Accel::Memory em = p.accel->embree_memory();
    const double tris = static_cast<double>(std::max<size_t>(1, p.scene.triangle_count()));
    // (allocated bytes: Embree reserves blocks it does not all touch, so the two can add up
    // to more than the resident peak)
    say("allocated per stored triangle: shapes %.1f B, Embree %.1f B (%.1f B at its peak)\n",
        static_cast<double>(shapes) / tris, static_cast<double>(em.now) / tris, static_cast<double>(em.peak) / tris);
  }
  if (f.print) std::fputs(text.c_str(), stdout);
  if (!f.json.empty() || json) {
    std::ostringstream js;
    js.precision(17);
    js << "{\n";
    js << "  \"samples_per_second\": {\"median\": " << med << ", \"min\": " << mn << ", \"max\": " << mx << "},\n";
    js << "  \"paths_per_second\": " << med << ", \"max_depth\": " << p.opt.est.max_depth
       << ", \"vertices_per_path\": " << vertices << ", \"vertices_per_second\": " << median(vps) << ",\n";
    js << "  \"rays_per_second\": {\"camera\": " << median(cam) << ", \"shadow\": " << median(sh)
       << ", \"bounce\": " << median(bo) << "},\n";
    js << "  \"time_to_first_pixel\": " << first_pixel << ",\n";
    js << "  \"load_seconds\": " << p.load_seconds << ",\n";
    js << "  \"bvh_seconds\": " << p.bvh_seconds << ",\n";
    js << "  \"peak_memory_bytes\": " << peak_memory_bytes() << ",\n";
    js << "  \"scene\": \"" << json_escape(p.scene.source) << "\",\n";
    js << "  \"triangles\": " << p.scene.triangle_count() << ",\n";
    js << "  \"triangles_rendered\": " << p.scene.instanced_triangle_count() << ", \"instances\": " << p.scene.instances.size()
       << ", \"peak_bytes_per_triangle\": " << per_triangle << ",\n";
    js << "  \"lights\": " << p.scene.lights.size() << ",\n";
    js << "  \"width\": " << p.scene.camera.width << ", \"height\": " << p.scene.camera.height << ",\n";
    js << "  \"spp\": " << spp << ", \"threads\": " << threads << ", \"repeat\": " << f.repeat
       << ", \"warmup\": " << f.warmup << ",\n";
    js << "  \"pipeline\": \"" << json_escape(last.pipeline) << "\",\n";
    js << "  \"bounce_rays\": \"" << (last.bounce_against_emitters ? "emitters" : "scene") << "\",\n";
    js << "  \"estimator\": \"" << json_escape(describe(p.opt.est)) << "\",\n";
    js << "  \"runs_samples_per_second\": [";
    for (size_t i = 0; i < sps.size(); ++i) js << (i ? ", " : "") << sps[i];
    js << "]\n}\n";
    if (json) *json = js.str();
    if (!f.json.empty()) write_text_file(f.json, js.str());
  }
  return 0;
}

int run_profile(const ProfileFlags& f, std::string* json) {
  std::string text;
  auto say = [&text](const char* fmt, auto... args) { appendf(text, fmt, args...); };
  // the outputs, before the work: writable, and not one file for both
  if (!f.json.empty()) check_output_path(f.json, {".json"});
  if (!f.trace.empty()) check_output_path(f.trace, {".json"});
  std::error_code ec;
  if (!f.json.empty() && !f.trace.empty() &&
      (f.json == f.trace || std::filesystem::weakly_canonical(f.json, ec) == std::filesystem::weakly_canonical(f.trace, ec)))
    throw std::invalid_argument("--trace and --json name one file (" + f.json + "): one would replace the other");
  Prepared p = prepare(f.render);
  Renderer renderer(p.scene, *p.accel, p.opt);
  const uint32_t spp = p.opt.est.spp;
  // a warm-up, then unprofiled and profiled renders alternately (3 each; medians), so the
  // cost of profiling is measured under the same machine load
  Film film;
  film.reset(p.scene.camera.width, p.scene.camera.height);
  renderer.render(film, 0, spp);
  std::vector<double> plain_s, prof_s, shares;
  Profile prof;
  RenderStats st;
  for (int r = 0; r < 3; ++r) {
    film.reset(p.scene.camera.width, p.scene.camera.height);
    plain_s.push_back(renderer.render(film, 0, spp).seconds);
    Profile pr;
    pr.trace = !f.trace.empty() && r == 2;
    pr.record_rays = f.roofline && r == 2;
    film.reset(p.scene.camera.width, p.scene.camera.height);
    const RenderStats s2 = renderer.render(film, 0, spp, &pr);
    prof_s.push_back(s2.seconds);
    shares.push_back((pr.stage_seconds[static_cast<int>(Stage::intersect_camera)] +
                      pr.stage_seconds[static_cast<int>(Stage::intersect_shadow)] +
                      pr.stage_seconds[static_cast<int>(Stage::intersect_bounce)]) /
                     (s2.seconds * pr.threads));
    if (r == 2) {
      prof = std::move(pr);
      st = s2;
    }
  }
  RenderStats plain = st;
  plain.seconds = median(plain_s);
  const double samples = static_cast<double>(st.samples);
  double stage_total = 0;
  for (double v : prof.stage_seconds) stage_total += v;
  const double thread_seconds = st.seconds * prof.threads;
  // the same figures as JSON (--json, and the Python module's tuile.profile)
  std::ostringstream js;
  js.precision(17);
  js << "{\n  \"scene\": \"" << json_escape(p.scene.source) << "\", \"width\": " << p.scene.camera.width
     << ", \"height\": " << p.scene.camera.height << ", \"spp\": " << spp << ", \"threads\": " << prof.threads
     << ",\n  \"pipeline\": \"" << json_escape(st.pipeline) << "\", \"bounce_rays\": \""
     << (st.bounce_against_emitters ? "emitters" : "scene") << "\",\n  \"stages\": [";
  bool first_stage = true;
  say("scene: %s, %dx%d, %u spp, %d thread(s), pipeline %s, bounce rays against the %s\n",
              p.scene.source.c_str(), p.scene.camera.width, p.scene.camera.height, spp, prof.threads,
              st.pipeline.c_str(), st.bounce_against_emitters ? "emitters" : "scene");
  say("%-18s %10s %7s %10s %10s\n", "stage", "ms", "%", "ns/sample", "Mrays/s");
  auto row = [&](const char* name, double sec, double rays) {
    say("%-18s %10.2f %6.1f%% %10.2f", name, sec * 1e3, 100.0 * sec / thread_seconds, sec * 1e9 / samples);
    if (rays > 0) say(" %10.2f", rays / sec * 1e-6);
    say("\n");
    js << (first_stage ? "\n" : ",\n") << "    {\"stage\": \"" << name << "\", \"ms\": " << sec * 1e3
       << ", \"percent\": " << 100.0 * sec / thread_seconds << ", \"ns_per_sample\": " << sec * 1e9 / samples
       << ", \"mrays_per_second\": " << (rays > 0 ? rays / sec * 1e-6 : 0.0) << "}";
    first_stage = false;
  };
  for (int k = 0; k < stage_count; ++k) {
    const Stage s = static_cast<Stage>(k);
    double rays = 0;
    if (s == Stage::intersect_camera) rays = static_cast<double>(st.rays_camera);
    if (s == Stage::intersect_shadow) rays = static_cast<double>(st.rays_shadow);
    // bounce rays and, when they run against the emitters, their visibility rays
    if (s == Stage::intersect_bounce) rays = static_cast<double>(st.rays_bounce + st.rays_bounce_visibility);
    row(stage_name(s), prof.stage_seconds[k], rays);
  }
  row("scheduling", std::max(0.0, thread_seconds - stage_total), 0);
  // the share as the median of the three profiled runs (the table above is the last one's)
  say("total: %.2f ms wall, %.4g samples/s; Embree share %.1f%% of thread time (median of 3 profiled runs, "
              "%.1f-%.1f%%)\n",
              st.seconds * 1e3, samples / st.seconds, 100.0 * median(shares),
              100.0 * *std::min_element(shares.begin(), shares.end()),
              100.0 * *std::max_element(shares.begin(), shares.end()));
  js << "\n  ],\n  \"wall_seconds\": " << st.seconds << ", \"samples_per_second\": " << samples / st.seconds
     << ",\n  \"embree_share\": {\"median\": " << median(shares)
     << ", \"min\": " << *std::min_element(shares.begin(), shares.end())
     << ", \"max\": " << *std::max_element(shares.begin(), shares.end()) << "},\n  \"unprofiled_samples_per_second\": "
     << samples / plain.seconds << ", \"profiled_samples_per_second\": " << samples / st.seconds;
  say("profiling cost: %.4g samples/s unprofiled vs %.4g profiled (%+.1f%%)\n",
              samples / plain.seconds, samples / st.seconds, 100.0 * (plain.seconds / st.seconds - 1.0));
  if (prof.depths > 0) {
    // paths: where they die and what compaction buys. Live lanes per packet: the vertex's
    // shading points over the packets their rays filled (compacted), and over the packets
    // of the tile's lanes (what the same rays would fill without compaction).
    say("paths (max depth %d, Russian roulette after vertex %d below throughput %g): %.4g paths/s, %.3g vertices per "
        "path\n",
                p.opt.est.max_depth, p.opt.est.rr_depth + 1, static_cast<double>(p.opt.est.rr_threshold), samples / st.seconds,
                1.0 + static_cast<double>(st.path_vertices) / samples);
    js << ",\n  \"paths_per_second\": " << samples / st.seconds << ", \"vertices_per_path\": "
       << 1.0 + static_cast<double>(st.path_vertices) / samples << ",\n  \"vertices\": [";
    // stage columns: what each vertex spends where (ms over all threads)
    const Stage cols[] = {Stage::camera_hits,    Stage::sample_lights,    Stage::intersect_shadow, Stage::sample_bsdf,
                          Stage::intersect_bounce, Stage::mis_weight, Stage::accumulate, Stage::media};
    const char* col_names[] = {"hits", "lights", "shadow", "BSDF", "bounce", "MIS", "accum", "media"};
    say("%-6s %10s %8s %7s %7s", "vertex", "paths", "alive", "lanes", "uncomp");
    for (const char* n : col_names) say(" %8s", n);
    say(" %9s %8s\n", "total ms", "ns/path");
    for (int d = 0; d < prof.depths; ++d) {
      const double* t = prof.depth_seconds[d];
      double sum = 0;
      for (int k = 0; k < stage_count; ++k) sum += t[k];
      const double pts = prof.depth_points[d];
      char label[16];
      std::snprintf(label, sizeof(label), d + 1 == profile_depths ? "%d+" : "%d", d + 1);
      say("%-6s %10.4g %7.2f%% %7.2f %7.2f", label, pts, 100.0 * pts / samples,
                  prof.depth_packets[d] > 0 ? pts / prof.depth_packets[d] : 0.0,
                  prof.depth_lane_packets[d] > 0 ? pts / prof.depth_lane_packets[d] : 0.0);
      for (Stage c : cols) say(" %8.2f", t[static_cast<int>(c)] * 1e3);
      say(" %9.2f %8.1f\n", sum * 1e3, pts > 0 ? sum * 1e9 / pts : 0.0);
      js << (d ? ",\n" : "\n") << "    {\"vertex\": \"" << label << "\", \"paths\": " << pts
         << ", \"alive_percent\": " << 100.0 * pts / samples
         << ", \"lanes\": " << (prof.depth_packets[d] > 0 ? pts / prof.depth_packets[d] : 0.0)
         << ", \"uncompacted_lanes\": " << (prof.depth_lane_packets[d] > 0 ? pts / prof.depth_lane_packets[d] : 0.0);
      for (size_t c = 0; c < std::size(cols); ++c)
        js << ", \"" << col_names[c] << "_ms\": " << t[static_cast<int>(cols[c])] * 1e3;
      js << ", \"total_ms\": " << sum * 1e3 << ", \"ns_per_path\": " << (pts > 0 ? sum * 1e9 / pts : 0.0) << "}";
    }
    js << "\n  ]";
    say("(lanes: live lanes per packet traced; uncomp: per packet of the tile's lanes, as without compaction; "
                "vertex 1's hits are the camera's, in the table above)\n");
  }
  if (f.roofline) {
    // median of 3 replays of the first pass's packets through Embree alone
    std::vector<double> t;
    for (int r = 0; r < 3; ++r) t.push_back(replay_rays(*p.accel, prof.rays, prof.threads));
    const double pass_samples = static_cast<double>(p.scene.camera.width) * p.scene.camera.height;
    const double bound = pass_samples / median(t);
    const double ours = samples / plain.seconds;
    std::vector<double> ts;
    for (int r = 0; r < 3; ++r) ts.push_back(replay_rays_stream(*p.accel, prof.rays, prof.threads));
    say("packets vs streams: the pass's rays take %.2f ms as 16-wide packets (tuile's layout), %.2f ms as "
                "rtcIntersectNp/rtcOccludedNp streams of one tile (medians of 3)\n",
                median(t) * 1e3, median(ts) * 1e3);
    say("roofline: Embree alone on one pass's %zu camera, %zu shadow, %zu bounce packets (and %zu against the "
                "emitters alone): %.4g samples/s; tuile %.4g samples/s = %.1f%% of that bound\n",
                prof.rays.camera.size(), prof.rays.shadow.size(), prof.rays.bounce.size(),
                prof.rays.bounce_emitters.size(), bound, ours, 100.0 * ours / bound);
    js << ",\n  \"roofline\": {\"packets_ms\": " << median(t) * 1e3 << ", \"streams_ms\": " << median(ts) * 1e3
       << ", \"bound_samples_per_second\": " << bound << ", \"samples_per_second\": " << ours
       << ", \"fraction_of_bound\": " << ours / bound << "}";
  }
  js << "\n}\n";
  if (json) *json = js.str();
  if (!f.json.empty()) write_text_file(f.json, js.str());
  if (!f.trace.empty()) {
    std::ofstream tr(f.trace);
    if (!tr) throw std::runtime_error(f.trace + ": cannot open for writing");
    tr << "{\"traceEvents\":[\n";
    bool first = true;
    for (const TraceEvent& e : prof.events) {
      tr << (first ? "" : ",\n") << "{\"name\":\"" << stage_name(e.stage) << "\",\"cat\":\"stage\",\"ph\":\"X\",\"ts\":"
         << e.start_us << ",\"dur\":" << e.dur_us << ",\"pid\":1,\"tid\":" << e.thread << ",\"args\":{\"tile\":"
         << e.tile << "}}";
      first = false;
    }
    tr << "\n],\"displayTimeUnit\":\"ms\"}\n";
    if (!tr) throw std::runtime_error(f.trace + ": error writing");
    say("trace: %zu events -> %s\n", prof.events.size(), f.trace.c_str());
  }
  if (f.print) std::fputs(text.c_str(), stdout);
  return 0;
}

}  // namespace tuile

namespace tuile {

void add_envmap_flags(CLI::App& app, EnvmapFlags& f) {
  app.add_option("input", f.in, "latitude-longitude map (2:1; theta from +z at the top row, phi from +x towards +y)")->required();
  app.add_option("output", f.out, "the equal-area square: .exr (float RGB) or .pfm")->required();
  app.add_option("--resolution", f.resolution, "texels per side (default: the input's width)")->check(CLI::Range(0, static_cast<int>(sky_map_max_res)));
  app.add_option("--samples", f.samples, "bilinear lookups per side of each texel, averaged (default 4)")->check(CLI::Range(1, 16));
}

int run_envmap(const EnvmapFlags& f) {
  check_output_path(f.out, {".exr", ".pfm"});  // before the work, not after it
  RgbImage in;
  std::string reason;
  if (!read_rgb_image(f.in, in, reason)) throw std::runtime_error(f.in + ": cannot read the map: " + reason);
  for (float v : in.rgb)  // (what an infinite light refuses in a map: a converted map must load)
    if (!std::isfinite(v) || v < 0 || v > 1e30f)
      throw std::runtime_error(f.in + ": the map has a NaN, infinite, negative or above-1e30 texel (" + std::to_string(v) + ")");
  if (in.width != 2 * in.height)
    std::fprintf(stderr, "tuile: warning: %s is %dx%d, not 2:1: read as latitude-longitude all the same\n", f.in.c_str(),
                 in.width, in.height);
  const int res = f.resolution > 0 ? f.resolution : in.width;
  if (res > 16384) throw std::invalid_argument("--resolution: at most 16384 texels per side (the input is " + std::to_string(in.width) + " wide)");
  const RgbImage out = latlong_to_equal_area(in, res, f.samples);
  const std::string ext = std::filesystem::path(f.out).extension().string();
  if (ext == ".pfm" || ext == ".PFM") write_pfm(f.out, out);
  else if (ext == ".exr" || ext == ".EXR") write_exr(f.out, out.width, out.height, out.rgb);
  else throw std::invalid_argument(f.out + ": the output must be .exr or .pfm");
  std::printf("tuile: %s (%dx%d latitude-longitude) -> %s (%dx%d equal-area octahedral)\n", f.in.c_str(), in.width, in.height,
              f.out.c_str(), res, res);
  return 0;
}

}  // namespace tuile
