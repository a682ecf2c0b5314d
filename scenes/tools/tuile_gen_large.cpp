// tuile_gen_large: writes a pbrt-v4 scene of a given size for scaling curves: a rolling
// terrain of N million triangles split over several binary PLY files, lit by K square
// area lights (one emissive PLY of K separate quads) hovering above it. With --instances N
// the terrain is an object (ObjectBegin) placed N times over a square field, each copy
// with its own turn, scale and place (ObjectInstance): N times the triangles rendered for
// the triangles stored once, and the lights spread over the field.
//
//   tuile_gen_large --out DIR [--mtris 2.5] [--lights 64] [--files 4] [--instances N] [--check]
//
// DIR/scene.pbrt is the scene; --check loads it back with tuile's reader and prints the
// load time.
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "scene/pbrt.h"

namespace {

void usage() {
  std::cerr << "usage: tuile_gen_large --out DIR [--mtris MILLIONS] [--lights K] [--files F] [--instances N] [--check]\n"
               "  --mtris   terrain triangles in millions (default 1)\n"
               "  --lights  number of square area lights (default 16)\n"
               "  --files   number of terrain PLY files (default: one per million triangles)\n"
               "  --instances  place the terrain N times as instances of one object (default 0: once, not an object)\n"
               "  --check   load the written scene with tuile and print the load time\n";
}

template <class T> void put(std::vector<char>& out, T v) {
  const char* p = reinterpret_cast<const char*>(&v);
  out.insert(out.end(), p, p + sizeof(T));
}

bool write_file(const std::filesystem::path& p, const std::vector<char>& data) {
  std::ofstream f(p, std::ios::binary);
  f.write(data.data(), std::streamsize(data.size()));
  return bool(f);
}

std::vector<char> ply_header(size_t nv, size_t nf) {
  const std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by tuile_gen_large\nelement vertex " +
                        std::to_string(nv) +
                        "\nproperty float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\n"
                        "element face " +
                        std::to_string(nf) + "\nproperty list uchar int vertex_indices\nend_header\n";
  return std::vector<char>(h.begin(), h.end());
}

float height(float x, float z) { return 0.4f * std::sin(0.9f * x) * std::cos(1.3f * z) + 0.1f * std::sin(3.1f * x + 2 * z); }

}  // namespace

int main(int argc, char** argv) {
  std::string out;
  double mtris = 1;
  long lights = 16, files = 0, instances = 0;
  bool check = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        usage();
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--out") out = value();
    else if (a == "--mtris") mtris = std::atof(value().c_str());
    else if (a == "--lights") lights = std::atol(value().c_str());
    else if (a == "--files") files = std::atol(value().c_str());
    else if (a == "--instances") instances = std::atol(value().c_str());
    else if (a == "--check") check = true;
    else if (a == "-h" || a == "--help") {
      usage();
      return 0;
    } else {
      std::cerr << "tuile_gen_large: unknown option " << a << "\n";
      usage();
      return 2;
    }
  }
  if (out.empty() || !(mtris > 0) || mtris > 2000 || lights < 0 || lights > 10000000 || files < 0 || instances < 0 ||
      instances > 10000000) {
    usage();
    return 2;
  }
  const double total = mtris * 1e6;
  if (files == 0) files = std::max(1l, long(std::ceil(mtris)));
  std::filesystem::create_directories(std::filesystem::path(out) / "models");

  // Terrain over [-10, 10]^2, cut into `files` strips along x; each strip is a grid of
  // nx x nz cells, two triangles per cell.
  const double per_file = total / double(files);
  const double aspect = 1.0 / double(files);  // strip width / depth
  const long nz = std::max(1l, long(std::sqrt(per_file / (2 * aspect))));
  const long nx = std::max(1l, long(per_file / (2.0 * nz)));
  const float size = 20;
  size_t tris_written = 0;
  std::string shapes;
  for (long f = 0; f < files; ++f) {
    const float x0 = -size / 2 + size * float(f) / float(files), x1 = -size / 2 + size * float(f + 1) / float(files);
    const size_t nv = size_t(nx + 1) * size_t(nz + 1), nf = size_t(2 * nx * nz);
    std::vector<char> data = ply_header(nv, nf);
    data.reserve(data.size() + nv * 20 + nf * 13);
    for (long j = 0; j <= nz; ++j)
      for (long i = 0; i <= nx; ++i) {
        const float u = float(i) / float(nx), v = float(j) / float(nz);
        const float x = x0 + (x1 - x0) * u, z = -size / 2 + size * v;
        put(data, x);
        put(data, height(x, z));
        put(data, z);
        put(data, u);
        put(data, v);
      }
    for (long j = 0; j < nz; ++j)
      for (long i = 0; i < nx; ++i) {
        const int32_t a = int32_t(j * (nx + 1) + i), b = a + 1, c = a + int32_t(nx + 1), d = c + 1;
        // counter-clockwise seen from +y
        put(data, uint8_t(3)), put(data, a), put(data, c), put(data, b);
        put(data, uint8_t(3)), put(data, b), put(data, c), put(data, d);
      }
    char name[64];
    std::snprintf(name, sizeof name, "models/terrain%03ld.ply", f);
    if (!write_file(std::filesystem::path(out) / name, data)) {
      std::cerr << "tuile_gen_large: cannot write " << name << "\n";
      return 1;
    }
    tris_written += nf;
    shapes += "Shape \"plymesh\" \"string filename\" [ \"" + std::string(name) + "\" ]\n";
  }

  // Instances: a square field of side x side cells of 24 m, each holding one copy of the
  // terrain (20 m), turned about y, scaled by 0.8 to 1.2 and moved within its cell.
  const long side_n = instances > 0 ? long(std::ceil(std::sqrt(double(instances)))) : 1;
  const float field = instances > 0 ? 24.f * float(side_n) : 20.f;
  // K lights on a square grid 3 m above the terrain (the field), facing down.
  if (lights > 0) {
    const long side = long(std::ceil(std::sqrt(double(lights))));
    const float span = 0.8f * field;
    const float pitch = span / float(side), half = 0.3f * std::min(pitch, 16.f / float(side) * 4.f);
    std::vector<char> data = ply_header(size_t(4 * lights), size_t(lights));
    for (long k = 0; k < lights; ++k) {
      const float cx = -span / 2 + pitch * (float(k % side) + 0.5f), cz = -span / 2 + pitch * (float(k / side) + 0.5f);
      const float corners[4][2] = {{cx - half, cz - half}, {cx + half, cz - half}, {cx + half, cz + half}, {cx - half, cz + half}};
      for (const auto& c : corners) {
        put(data, c[0]), put(data, 3.0f), put(data, c[1]);
        put(data, 0.f), put(data, 0.f);
      }
    }
    for (long k = 0; k < lights; ++k) {
      const int32_t b = int32_t(4 * k);
      put(data, uint8_t(4)), put(data, b), put(data, b + 1), put(data, b + 2), put(data, b + 3);  // normal -y
    }
    if (!write_file(std::filesystem::path(out) / "models/lights.ply", data)) {
      std::cerr << "tuile_gen_large: cannot write lights.ply\n";
      return 1;
    }
  }

  std::ofstream scene(std::filesystem::path(out) / "scene.pbrt");
  scene << "# Generated by tuile_gen_large: " << tris_written << " terrain triangles in " << files << " PLY files, "
        << lights << " quad lights.\n"
        << "Film \"rgb\" \"integer xresolution\" [ 960 ] \"integer yresolution\" [ 540 ] \"string filename\" [ \"large.exr\" ]\n"
        << "Sampler \"independent\" \"integer pixelsamples\" [ 4 ]\n"
        << "Scale -1 1 1\nLookAt 0 " << 0.45f * field << " " << 0.7f * field << "  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 45 ]\n\nWorldBegin\n"
        << "Material \"diffuse\" \"rgb reflectance\" [ 0.55 0.5 0.45 ]\n";
  if (instances > 0) {
    scene << "LightSource \"distant\" \"point3 from\" [ 1 3 2 ] \"point3 to\" [ 0 0 0 ] \"rgb L\" [ 2 2 2 ]\n"
          << "ObjectBegin \"terrain\"\n" << shapes << "ObjectEnd\n";
    uint32_t h = 12345;  // a fixed sequence: the same file every time
    auto next = [&h] {
      h ^= h << 13, h ^= h >> 17, h ^= h << 5;
      return float(h) / 4294967296.f;
    };
    for (long k = 0; k < instances; ++k) {
      const float cx = -field / 2 + 24.f * (float(k % side_n) + 0.5f), cz = -field / 2 + 24.f * (float(k / side_n) + 0.5f);
      const float jx = 1.5f * (next() - 0.5f), jz = 1.5f * (next() - 0.5f), turn = 360.f * next(), sc = 0.8f + 0.4f * next();
      scene << "AttributeBegin\n  Translate " << cx + jx << " 0 " << cz + jz << "\n  Rotate " << turn << " 0 1 0\n  Scale " << sc << " "
            << sc << " " << sc << "\n  ObjectInstance \"terrain\"\nAttributeEnd\n";
    }
  } else {
    scene << shapes;
  }
  if (lights > 0)
    scene << "AttributeBegin\n    AreaLightSource \"diffuse\" \"rgb L\" [ 8 8 8 ]\n"
             "    Material \"diffuse\" \"rgb reflectance\" [ 0 0 0 ]\n"
             "    Shape \"plymesh\" \"string filename\" [ \"models/lights.ply\" ]\nAttributeEnd\n";
  scene.close();
  if (!scene) {
    std::cerr << "tuile_gen_large: cannot write scene.pbrt\n";
    return 1;
  }
  std::cout << out << "/scene.pbrt: " << tris_written << " triangles in " << files << " files, " << lights << " lights";
  if (instances > 0) std::cout << ", " << instances << " instances (" << double(tris_written) * double(instances) << " triangles rendered)";
  std::cout << "\n";

  if (check) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      const tuile::Scene s = tuile::load_pbrt((std::filesystem::path(out) / "scene.pbrt").string());
      const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      size_t tris = 0;
      for (const auto& m : s.meshes) tris += m.triangle_count();
      std::cout << "loaded " << tris << " triangles in " << s.meshes.size() << " meshes in " << dt << " s\n";
    } catch (const std::exception& e) {
      std::cerr << e.what() << "\n";
      return 1;
    }
  }
  return 0;
}
