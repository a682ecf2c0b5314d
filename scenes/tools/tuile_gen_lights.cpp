// tuile_gen_lights: writes a pbrt-v4 scene with many small one-sided emissive triangles of
// very unequal power, for the scaling curves of light selection (issue #19, many lights).
//
//   tuile_gen_lights --out DIR --emitters N [--seed S] [--decades D] [--levels G]
//                    [--res WxH] [--spp S] [--max-depth D] [--power W] [--check]
//
// The room is 8 x 3 x 12 m (x in [-4, 4], y in [0, 3], z in [-6, 6]) with two partitions, a
// ceiling beam, a pillar and three blocks, all diffuse, so that most sources are hidden
// from most shading points. The camera stands near the z = 6 wall looking towards -z.
//
// The N emitters are separate triangles (no two share a vertex, so none pairs into a
// parallelogram source) in about 2 sqrt(N) clusters: 40% of the clusters on the ceiling,
// 40% on the walls (by wall area), 20% floating beside the occluders. Every triangle is
// one-sided and faces into the room: those on the ceiling and walls face along the
// surface's inward normal (2 to 3 mm in front of it); a floating one faces the room's
// centre (0, 1.5, 0) within 64 degrees, so the centre is in front of every emitter.
// Triangle sizes are log-uniform over one decade (largest 0.3 m for N <= 1000, shrinking
// as 1 / sqrt(N) above, so the total emitting area does not grow with N). pbrt gives one
// radiance per AreaLightSource, so the triangles are split evenly (by a seeded shuffle)
// over G meshes (default 64), one binary PLY each, whose luminances are log-spaced over
// exactly D decades (default 4); each level is tinted warm, neutral or cool, normalised to
// luminance 1. Radiances are then scaled so that the total emitted power is W (default
// 1500 W, which lights the walls at radiance of order 1 with maxdepth 1).
//
// Output: DIR/scene.pbrt and DIR/models/emitters_GGG.ply. The output depends only on the
// options (not on DIR): random numbers are std::mt19937_64 words (whose sequence the
// standard fixes) turned into doubles by explicit arithmetic.
//
// --check loads DIR/scene.pbrt with tuile's reader, prints the parse and finalize times
// and the number of light sources, and fails unless it is exactly N.
#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <string>
#include <system_error>
#include <vector>

#include "scene/pbrt.h"

namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;
constexpr long kMaxEmitters = 10000000;

[[noreturn]] void fail_usage(const std::string& message) {
  std::cerr << "tuile_gen_lights: " << message << "\n(run tuile_gen_lights --help for the options)\n";
  std::exit(2);
}

void usage() {
  std::cout << "usage: tuile_gen_lights --out DIR --emitters N [options]\n"
               "  --out DIR        output directory (created): DIR/scene.pbrt, DIR/models/*.ply\n"
               "  --emitters N     number of emissive triangles, 1..10000000\n"
               "  --seed S         random seed, 0..2^64-1 (default 1)\n"
               "  --decades D      radiances span 10^D, D in [0, 8] (default 4)\n"
               "  --levels G       radiance levels = emissive meshes, 1..1024 (default 64; at most N)\n"
               "  --res WxH        film resolution (default 256x192)\n"
               "  --spp S          Sampler pixelsamples (default 16)\n"
               "  --max-depth D    Integrator maxdepth (default 1: direct lighting)\n"
               "  --power W        total emitted power in watts (default 1500)\n"
               "  --view V         room (default: down the room, many emitters in view) or floor (straight\n"
               "                   down from under the ceiling: the lit floor and blocks, few emitters in\n"
               "                   view, so an image's error is the light sampling's, not the pixel\n"
               "                   antialiasing of bright emitters)\n"
               "  --check          load the scene with tuile and print the light count and load time\n";
}

// Whole-string numeric parsing: anything else (empty, trailing characters, out of range)
// is an error naming the option.
long parse_long(const std::string& opt, const std::string& s, long lo, long hi) {
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || *end != '\0' || errno == ERANGE || v < lo || v > hi)
    fail_usage(opt + ": expected an integer in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got '" + s + "'");
  return v;
}

uint64_t parse_u64(const std::string& opt, const std::string& s) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
  if (s.empty() || s[0] == '-' || s[0] == '+' || *end != '\0' || errno == ERANGE)
    fail_usage(opt + ": expected an integer in 0..18446744073709551615, got '" + s + "'");
  return uint64_t(v);
}

double parse_double(const std::string& opt, const std::string& s, double lo, double hi) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || *end != '\0' || !std::isfinite(v) || v < lo || v > hi) {
    char range[64];
    std::snprintf(range, sizeof range, "[%g, %g]", lo, hi);
    fail_usage(opt + ": expected a number in " + range + ", got '" + s + "'");
  }
  return v;
}

struct V3 {
  double x = 0, y = 0, z = 0;
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double length(V3 a) { return std::sqrt(dot(a, a)); }
V3 normalize(V3 a) { return (1 / length(a)) * a; }

// Tangents t, b with cross(t, b) = n (unit n): a counter-clockwise turn from t to b is
// counter-clockwise seen from the side n points to.
void frame(V3 n, V3& t, V3& b) {
  const V3 a = std::fabs(n.x) < 0.9 ? V3{1, 0, 0} : V3{0, 1, 0};
  t = normalize(cross(a, n));
  b = cross(n, t);
}

// Uniform doubles in [0, 1) from the 53 high bits of a 64-bit Mersenne Twister word.
struct Rng {
  std::mt19937_64 g;
  explicit Rng(uint64_t seed) : g(seed) {}
  double u() { return double(g() >> 11) * 0x1p-53; }
  size_t below(size_t n) { return std::min(n - 1, size_t(u() * double(n))); }
  V3 unit() {
    const double z = 1 - 2 * u(), phi = 2 * kPi * u(), r = std::sqrt(std::max(0.0, 1 - z * z));
    return {r * std::cos(phi), r * std::sin(phi), z};
  }
};

struct Box {
  V3 lo, hi;
  bool contains(V3 p, double margin) const {
    return p.x > lo.x - margin && p.x < hi.x + margin && p.y > lo.y - margin && p.y < hi.y + margin &&
           p.z > lo.z - margin && p.z < hi.z + margin;
  }
};

const Box kRoom{{-4, 0, -6}, {4, 3, 6}};
const V3 kCentre{0, 1.5, 0};

struct Occluder {
  Box box;
  const char* material;
  const char* what;
};
const std::array<Occluder, 7> kOccluders = {{
    {{{-4, 0, -1.05}, {-0.6, 2.2, -0.95}}, "partition", "partition from the x = -4 wall"},
    {{{0.8, 0, -3.55}, {4, 2.4, -3.45}}, "partition", "partition from the x = 4 wall"},
    {{{-4, 2.5, 1.45}, {4, 3, 1.55}}, "partition", "beam under the ceiling"},
    {{{-0.3, 0, -2.3}, {0.3, 3, -1.7}}, "pillar", "pillar"},
    {{{1.2, 0, 0.5}, {2.4, 1.0, 1.7}}, "red", "block"},
    {{{-2.8, 0, -4.6}, {-1.6, 1.6, -3.4}}, "green", "block"},
    {{{-3.2, 0, 2.6}, {-2.4, 0.8, 3.4}}, "blue", "block"},
}};

bool in_occluder(V3 p, double margin) {
  for (const Occluder& o : kOccluders)
    if (o.box.contains(p, margin)) return true;
  return false;
}

// A planar face: centre c, unit normal n, tangents t, b (cross(t, b) = n), half sizes ht, hb.
struct Face {
  V3 c, n, t, b;
  double ht, hb;
};

// The six faces of an axis-aligned box, normals outwards (inwards when `inward`).
std::vector<Face> box_faces(const Box& bx, bool inward) {
  std::vector<Face> faces;
  const V3 c = 0.5 * (bx.lo + bx.hi), h = 0.5 * (bx.hi - bx.lo);
  for (int axis = 0; axis < 3; ++axis)
    for (int s : {-1, 1}) {
      V3 n;
      (axis == 0 ? n.x : axis == 1 ? n.y : n.z) = s;
      Face f;
      f.c = c + (axis == 0 ? h.x : axis == 1 ? h.y : h.z) * n;
      f.n = inward ? -1.0 * n : n;
      frame(f.n, f.t, f.b);
      f.ht = std::fabs(dot(f.t, h));
      f.hb = std::fabs(dot(f.b, h));
      faces.push_back(f);
    }
  return faces;
}

std::string fmt(double v) {
  char s[32];
  std::snprintf(s, sizeof s, "%.9g", v);
  return s;
}

// A trianglemesh of the given faces (two triangles each, wound counter-clockwise about
// the face normal).
std::string trianglemesh(const std::vector<Face>& faces) {
  std::string p, idx;
  for (size_t i = 0; i < faces.size(); ++i) {
    const Face& f = faces[i];
    if (i) p += "\n           ";
    const V3 corners[4] = {f.c - f.ht * f.t - f.hb * f.b, f.c + f.ht * f.t - f.hb * f.b, f.c + f.ht * f.t + f.hb * f.b,
                           f.c - f.ht * f.t + f.hb * f.b};
    for (const V3& v : corners)
      for (double x : {v.x, v.y, v.z}) p.append(" ").append(fmt(x));
    const size_t b = 4 * i;
    for (size_t k : {b, b + 1, b + 2, b, b + 2, b + 3}) idx.append(" ").append(std::to_string(k));
  }
  return "    Shape \"trianglemesh\"\n        \"point3 P\" [" + p + " ]\n        \"integer indices\" [" + idx + " ]\n";
}

void put_u32(std::vector<char>& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(char((v >> (8 * i)) & 0xff));  // little-endian
}

struct Options {
  std::string out;
  long emitters = -1, levels = 64, width = 256, height = 192, spp = 16, max_depth = 1;
  uint64_t seed = 1;
  double decades = 4, power = 1500;
  bool check = false;
  std::string view = "room";
};

// The options that decide the output, for the file's header (DIR left out, so that the
// same options give the same bytes anywhere).
std::string describe(const Options& o) {
  return "--emitters " + std::to_string(o.emitters) + " --seed " + std::to_string(o.seed) + " --decades " +
         fmt(o.decades) + " --levels " + std::to_string(o.levels) + " --res " + std::to_string(o.width) + "x" +
         std::to_string(o.height) + " --spp " + std::to_string(o.spp) + " --max-depth " + std::to_string(o.max_depth) +
         " --power " + fmt(o.power) + (o.view == "room" ? "" : " --view " + o.view);
}

int check_scene(const Options& o) {
  const fs::path path = fs::path(o.out) / "scene.pbrt";
  try {
    const auto t0 = std::chrono::steady_clock::now();
    tuile::Scene s = tuile::load_pbrt(path.string());
    const auto t1 = std::chrono::steady_clock::now();
    tuile::finalize_scene(s);
    const auto t2 = std::chrono::steady_clock::now();
    size_t tris = 0, emissive = 0;
    for (const auto& m : s.meshes) {
      tris += m.triangle_count();
      emissive += m.emissive();
    }
    double lo = 1e300, hi = 0, power = 0;
    for (const auto& l : s.lights) {
      const double y = 0.2126 * l.radiance.r + 0.7152 * l.radiance.g + 0.0722 * l.radiance.b;
      lo = std::min(lo, y);
      hi = std::max(hi, y);
      power += l.power;
    }
    const double parse = std::chrono::duration<double>(t1 - t0).count();
    const double fin = std::chrono::duration<double>(t2 - t1).count();
    std::cout << "loaded " << s.lights.size() << " lights (" << emissive << " emissive meshes, " << tris
              << " triangles in all; luminance " << fmt(lo) << " .. " << fmt(hi) << ", total power " << fmt(power)
              << " W) in " << fmt(parse + fin) << " s (parse " << fmt(parse) << " s, finalize " << fmt(fin) << " s)\n";
    if (s.lights.size() != size_t(o.emitters)) {
      std::cerr << "tuile_gen_lights: --check: expected " << o.emitters << " lights, tuile loaded " << s.lights.size()
                << "\n";
      return 1;
    }
  } catch (const std::exception& e) {
    std::cerr << "tuile_gen_lights: --check: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) fail_usage(a + " needs a value");
      return argv[++i];
    };
    if (a == "--out") o.out = value();
    else if (a == "--emitters") o.emitters = parse_long(a, value(), 1, kMaxEmitters);
    else if (a == "--seed") o.seed = parse_u64(a, value());
    else if (a == "--decades") o.decades = parse_double(a, value(), 0, 8);
    else if (a == "--levels") o.levels = parse_long(a, value(), 1, 1024);
    else if (a == "--spp") o.spp = parse_long(a, value(), 1, 1 << 20);
    else if (a == "--max-depth") o.max_depth = parse_long(a, value(), 1, 100000);
    else if (a == "--power") o.power = parse_double(a, value(), 1e-6, 1e12);
    else if (a == "--res") {
      const std::string v = value();
      const size_t x = v.find('x');
      if (x == std::string::npos) fail_usage("--res: expected WxH (e.g. 256x192), got '" + v + "'");
      o.width = parse_long("--res width", v.substr(0, x), 1, 32768);
      o.height = parse_long("--res height", v.substr(x + 1), 1, 32768);
    } else if (a == "--view") {
      o.view = value();
      if (o.view != "room" && o.view != "floor") fail_usage("--view: expected room or floor, got '" + o.view + "'");
    } else if (a == "--check") o.check = true;
    else if (a == "-h" || a == "--help") {
      usage();
      return 0;
    } else fail_usage("unknown option '" + a + "'");
  }
  if (o.out.empty()) fail_usage("--out DIR is required");
  if (o.emitters < 0) fail_usage("--emitters N is required");

  const auto t_start = std::chrono::steady_clock::now();
  const fs::path dir(o.out);
  std::error_code ec;
  fs::create_directories(dir / "models", ec);
  if (ec) {
    std::cerr << "tuile_gen_lights: cannot create " << (dir / "models").string() << ": " << ec.message() << "\n";
    return 1;
  }

  const size_t n = size_t(o.emitters);
  const size_t levels = std::min(size_t(o.levels), n);
  Rng rng(o.seed);

  // Radiance level of each triangle: levels used n / G times each (+-1), in seeded order.
  std::vector<uint16_t> level(n);
  for (size_t i = 0; i < n; ++i) level[i] = uint16_t(i % levels);
  for (size_t i = n; i-- > 1;) std::swap(level[i], level[rng.below(i + 1)]);

  // Sizes: the distance from a triangle's centre to its vertices is s (0.7 .. 1), s
  // log-uniform in [s_max / 10, s_max].
  const double s_max = 0.3 * std::min(1.0, std::sqrt(1000.0 / double(n)));
  const size_t clusters = std::clamp<size_t>(size_t(std::lround(2 * std::sqrt(double(n)))), 1, n);
  const double per_cluster = double(n) / double(clusters);
  // cluster radius: the triangles (mean area about 0.2 s_max^2) cover about half its disc
  const double radius = s_max * (std::sqrt(0.14 * per_cluster) + 0.5);

  const std::vector<Face> room_faces = box_faces(kRoom, true);  // -x +x -y +y -z +z walls, normals inwards
  // Cluster surfaces: the ceiling (weight 0.4) and the four walls (0.4 by area).
  struct Surface {
    Face f;
    double weight;
  };
  std::vector<Surface> surfaces = {{room_faces[3], 0.4}};
  for (int w : {0, 1, 4, 5}) {
    const Face& f = room_faces[size_t(w)];
    surfaces.push_back({f, 0.4 * (f.ht * f.hb) / (2 * 6 * 1.5 + 2 * 4 * 1.5)});
  }

  std::vector<std::vector<float>> tris(levels);  // 9 floats per triangle, per level
  for (auto& t : tris) t.reserve(9 * (n / levels + 1));
  std::vector<double> level_area(levels, 0.0);

  auto emit = [&](size_t i, V3 c, V3 nrm, double s) {
    V3 t, b;
    frame(nrm, t, b);
    const double phi0 = 2 * kPi * rng.u();
    float v[9];
    for (int k = 0; k < 3; ++k) {
      const double phi = phi0 + 2 * kPi * k / 3 + 0.6 * (rng.u() - 0.5), r = s * (0.7 + 0.3 * rng.u());
      const V3 p = c + (r * std::cos(phi)) * t + (r * std::sin(phi)) * b;
      v[3 * k] = float(p.x), v[3 * k + 1] = float(p.y), v[3 * k + 2] = float(p.z);
    }
    const V3 p0{v[0], v[1], v[2]}, p1{v[3], v[4], v[5]}, p2{v[6], v[7], v[8]};
    level_area[level[i]] += 0.5 * length(cross(p1 - p0, p2 - p0));
    tris[level[i]].insert(tris[level[i]].end(), v, v + 9);
  };

  size_t next = 0;
  for (size_t k = 0; k < clusters; ++k) {
    const size_t count = (k + 1) * n / clusters - k * n / clusters;
    const double pick = rng.u();
    if (pick < 0.8) {
      // on the ceiling or a wall: a disc of `radius` away from the edges and the occluders
      double acc = 0;
      size_t si = surfaces.size() - 1;
      for (size_t j = 0; j < surfaces.size(); ++j)
        if (pick < (acc += surfaces[j].weight)) {
          si = j;
          break;
        }
      const Face& f = surfaces[si].f;
      const bool wall = si != 0;
      const double margin = radius + s_max + 0.01;
      const double mt = std::max(0.0, f.ht - margin), mb = std::max(0.0, f.hb - margin);
      V3 c;
      for (int tries = 0; tries < 64; ++tries) {
        c = f.c + (mt * (2 * rng.u() - 1)) * f.t + (mb * (2 * rng.u() - 1)) * f.b;
        if (wall && c.y < 0.4 + radius) c.y = 0.4 + radius;  // wall clusters above 0.4 m
        if (!in_occluder(c, 0.1)) break;
      }
      for (size_t j = 0; j < count; ++j, ++next) {
        const double s = s_max * std::pow(10.0, rng.u() - 1);
        V3 p;
        for (int tries = 0; tries < 64; ++tries) {
          const double rr = radius * std::sqrt(rng.u()), a = 2 * kPi * rng.u();
          p = c + (rr * std::cos(a)) * f.t + (rr * std::sin(a)) * f.b + (0.002 + 0.001 * rng.u()) * f.n;
          if (!in_occluder(p, s)) break;
        }
        emit(next, p, f.n, s);
      }
    } else {
      // floating beside an occluder: a ball of `radius` off one of its faces (not the
      // bottom), clear of the walls, the occluders and the room's centre
      V3 c;
      bool placed = false;
      for (int tries = 0; tries < 100000 && !placed; ++tries) {
        const Occluder& oc = kOccluders[rng.below(kOccluders.size())];
        const std::vector<Face> faces = box_faces(oc.box, false);
        const size_t fi = rng.below(5);
        const Face& f = faces[fi >= 2 ? fi + 1 : fi];  // faces[2] is the bottom (-y)
        c = f.c + (f.ht * (2 * rng.u() - 1)) * f.t + (f.hb * (2 * rng.u() - 1)) * f.b +
            (radius + 0.1 + 0.3 * rng.u()) * f.n;
        const double m = radius + s_max + 0.05;
        placed = c.x > kRoom.lo.x + m && c.x < kRoom.hi.x - m && c.y > kRoom.lo.y + m && c.y < kRoom.hi.y - m &&
                 c.z > kRoom.lo.z + m && c.z < kRoom.hi.z - m && !in_occluder(c, radius + 0.05) &&
                 length(c - kCentre) > radius + 0.3;
      }
      if (!placed) {
        std::cerr << "tuile_gen_lights: no room for a floating cluster (internal error)\n";
        return 1;
      }
      for (size_t j = 0; j < count; ++j, ++next) {
        const double s = s_max * std::pow(10.0, rng.u() - 1);
        V3 p;
        for (int tries = 0; tries < 64; ++tries) {
          V3 d;
          do d = V3{2 * rng.u() - 1, 2 * rng.u() - 1, 2 * rng.u() - 1};
          while (dot(d, d) > 1);
          p = c + radius * d;
          if (!in_occluder(p, s) && length(p - kCentre) > 0.3) break;
        }
        // within asin(0.9) = 64 degrees of the direction to the centre (cosine >= 0.1)
        const V3 nrm = normalize(normalize(kCentre - p) + 0.9 * rng.unit());
        emit(next, p, nrm, s);
      }
    }
  }

  // Luminance 10^(D g / (G - 1)) per level, scaled to the total power; tints of luminance 1.
  const double tints[3][3] = {{1.0, 0.82, 0.62}, {1.0, 1.0, 1.0}, {0.7, 0.85, 1.0}};
  std::vector<double> rel(levels);
  double phi = 0;
  for (size_t g = 0; g < levels; ++g) {
    rel[g] = levels > 1 ? std::pow(10.0, o.decades * double(g) / double(levels - 1)) : 1.0;
    phi += kPi * rel[g] * level_area[g];
  }
  const double scale = o.power / phi;

  std::string shapes;
  for (size_t g = 0; g < levels; ++g) {
    const size_t nt = tris[g].size() / 9;
    const std::string header = "ply\nformat binary_little_endian 1.0\ncomment written by tuile_gen_lights\nelement vertex " +
                               std::to_string(3 * nt) +
                               "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                               std::to_string(nt) + "\nproperty list uchar int vertex_indices\nend_header\n";
    std::vector<char> data(header.begin(), header.end());
    data.reserve(data.size() + nt * (36 + 13));
    for (float f : tris[g]) put_u32(data, std::bit_cast<uint32_t>(f));
    for (uint32_t t = 0; t < nt; ++t) {
      data.push_back(3);
      for (uint32_t k = 0; k < 3; ++k) put_u32(data, 3 * t + k);
    }
    char name[64];
    std::snprintf(name, sizeof name, "models/emitters_%03zu.ply", g);
    std::ofstream f(dir / name, std::ios::binary);
    f.write(data.data(), std::streamsize(data.size()));
    f.close();
    if (!f) {
      std::cerr << "tuile_gen_lights: cannot write " << (dir / name).string() << "\n";
      return 1;
    }
    const double* tint = tints[g % 3];
    const double y = 0.2126 * tint[0] + 0.7152 * tint[1] + 0.0722 * tint[2], L = scale * rel[g] / y;
    shapes += "AttributeBegin  # level " + std::to_string(g) + ": " + std::to_string(nt) + " triangles\n" +
              "    AreaLightSource \"diffuse\" \"rgb L\" [ " + fmt(L * tint[0]) + " " + fmt(L * tint[1]) + " " +
              fmt(L * tint[2]) + " ]\n    NamedMaterial \"emitter\"\n    Shape \"plymesh\" \"string filename\" [ \"" +
              name + "\" ]\nAttributeEnd\n";
  }

  std::string occluders;
  for (const Occluder& oc : kOccluders)
    occluders += "# " + std::string(oc.what) + "\nNamedMaterial \"" + oc.material + "\"\n" + trianglemesh(box_faces(oc.box, false));

  std::ofstream scene(dir / "scene.pbrt");
  scene << "# Generated by tuile_gen_lights " << describe(o) << "\n"
        << "# " << n << " one-sided emissive triangles in " << clusters << " clusters, " << levels
        << " radiance levels over " << fmt(o.decades) << " decades, total power " << fmt(o.power) << " W.\n"
        << "# An 8 x 3 x 12 m room with two partitions, a ceiling beam, a pillar and three blocks.\n"
        << "Film \"rgb\" \"integer xresolution\" [ " << o.width << " ] \"integer yresolution\" [ " << o.height
        << " ]\n    \"string filename\" [ \"lights.exr\" ]\n"
        << "Sampler \"independent\" \"integer pixelsamples\" [ " << o.spp << " ]\n"
        << "Integrator \"volpath\" \"integer maxdepth\" [ " << o.max_depth << " ] \"string lightsampler\" \"bvh\"\n"
        << "PixelFilter \"box\"\n"
        << (o.view == "floor" ? "Scale -1 1 1\nLookAt 0 2.6 0  0 0 0  0 0 -1\nCamera \"perspective\" \"float fov\" [ 80 ]\n\n"
                              : "Scale -1 1 1\nLookAt 0 1.7 5.6  0 1.1 -6  0 1 0\nCamera \"perspective\" \"float fov\" [ 62 ]\n\n")
        << "WorldBegin\n"
        << "MakeNamedMaterial \"wall\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.6 0.6 0.58 ]\n"
        << "MakeNamedMaterial \"floor\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.45 0.4 0.35 ]\n"
        << "MakeNamedMaterial \"partition\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.5 0.5 0.5 ]\n"
        << "MakeNamedMaterial \"pillar\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.55 0.5 0.4 ]\n"
        << "MakeNamedMaterial \"red\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.6 0.2 0.15 ]\n"
        << "MakeNamedMaterial \"green\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.2 0.5 0.2 ]\n"
        << "MakeNamedMaterial \"blue\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0.2 0.3 0.6 ]\n"
        << "MakeNamedMaterial \"emitter\" \"string type\" \"diffuse\" \"rgb reflectance\" [ 0 0 0 ]\n\n"
        << "# floor\nNamedMaterial \"floor\"\n" << trianglemesh({room_faces[2]})
        << "# walls and ceiling, facing in\nNamedMaterial \"wall\"\n"
        << trianglemesh({room_faces[0], room_faces[1], room_faces[3], room_faces[4], room_faces[5]}) << occluders
        << "\n# emitters: one mesh per radiance level\n"
        << shapes;
  scene.close();
  if (!scene) {
    std::cerr << "tuile_gen_lights: cannot write " << (dir / "scene.pbrt").string() << "\n";
    return 1;
  }
  const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  std::cout << (dir / "scene.pbrt").string() << ": " << n << " emitters in " << clusters << " clusters, " << levels
            << " levels over " << fmt(o.decades) << " decades, written in " << fmt(dt) << " s\n";
  return o.check ? check_scene(o) : 0;
}
