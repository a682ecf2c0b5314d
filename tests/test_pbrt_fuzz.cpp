// Mutation fuzzing of the pbrt-v4 reader: valid scenes are damaged at random (byte
// flips, deletions, duplicated tokens, truncation, "nan", huge numbers, stray brackets
// and quotes) and every result must load or throw SceneError -- no other exception, no
// crash (run it under -DTUILE_SANITIZE=ON), and no input may take long.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "scene/pbrt.h"

namespace fs = std::filesystem;
using namespace tuile;

namespace {

const char* const inline_scenes[] = {
    R"(Film "rgb" "integer xresolution" [ 64 ] "integer yresolution" [ 48 ] "string filename" "f.exr"
Sampler "halton" "integer pixelsamples" 8
Integrator "path" "integer maxdepth" 1 "string lightsampler" "power"
Scale -1 1 1
LookAt 0 1 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 40 ] "float screenwindow" [ -1 1 -0.75 0.75 ]
WorldBegin
MakeNamedMaterial "m" "string type" "diffuse" "rgb reflectance" [ 0.5 0.4 0.3 ]
MakeNamedMaterial "c" "string type" "conductor" "spectrum eta" "metal-Cu-eta"
Texture "chk" "spectrum" "checkerboard" "float uscale" 4 "float vscale" 4 "rgb tex1" [1 0 0]
Texture "img" "spectrum" "imagemap" "string filename" "fuzz.tga"
Texture "sc" "spectrum" "scale" "texture tex" "img" "float scale" 0.5
Material "diffuse" "texture reflectance" "chk"
NamedMaterial "m"
AttributeBegin
  Translate 0 2 0
  Rotate 30 1 0 0
  AreaLightSource "diffuse" "blackbody L" 5000 "float power" 40
  Shape "trianglemesh" "point3 P" [ -1 0 -1 1 0 -1 1 0 1 -1 0 1 ] "integer indices" [ 0 1 2 0 2 3 ]
    "point2 uv" [ 0 0 1 0 1 1 0 1 ] "normal N" [ 0 -1 0 0 -1 0 0 -1 0 0 -1 0 ]
AttributeEnd
Shape "sphere" "float radius" 0.5
Shape "disk" "float radius" 2 "float innerradius" 0.5
Shape "bilinearmesh" "point3 P" [ 0 0 0 1 0 0 0 1 0 1 1 0 ]
LightSource "spot" "point3 from" [ 0 3 0 ] "point3 to" [ 0 0 0 ] "rgb I" [ 5 5 5 ]
LightSource "distant" "point3 to" [ 0 -1 0 ] "rgb L" [ 1 1 1 ]
)",
    R"(WorldBegin
ObjectBegin "thing"
  Shape "plymesh" "string filename" "fuzz.ply"
ObjectEnd
TransformBegin
  Translate 1 0 0
  ObjectInstance "thing"
TransformEnd
CoordinateSystem "here"
AttributeBegin
  ReverseOrientation
  Scale 1 -1 1
  AreaLightSource "diffuse" "rgb L" [ 4 4 4 ] "bool twosided" true
  Shape "plymesh" "string filename" "fuzz_ascii.ply"
AttributeEnd
CoordSysTransform "here"
Include "fuzz_inc.pbrt"
LightSource "point" "rgb I" [ 1 2 3 ] "point3 from" [ 0 4 0 ] "float power" 10
MakeNamedMedium "fog" "string type" "homogeneous"
MediumInterface "fog" ""
)",
};

template <class T> void put(std::string& s, T v) { s.append(reinterpret_cast<const char*>(&v), sizeof(T)); }

std::string fuzz_ply() {
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n";
  const float v[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  for (float x : v) put(s, x);
  put(s, uint8_t(3)), put(s, 0), put(s, 1), put(s, 2);
  put(s, uint8_t(4)), put(s, 0), put(s, 1), put(s, 2), put(s, 3);
  return s;
}

const fs::path& fuzz_dir() {
  static const fs::path dir = [] {
    fs::path d = fs::temp_directory_path() /
                 ("tuile_fuzz_pbrt_" + std::to_string(std::chrono::steady_clock::now().time_since_epoch().count()));
    fs::create_directories(d);
    std::ofstream(d / "fuzz.ply", std::ios::binary) << fuzz_ply();
    std::ofstream(d / "fuzz_ascii.ply") << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                           "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                           "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    std::ofstream(d / "fuzz_inc.pbrt") << "Shape \"sphere\" \"float radius\" 0.25\n";
    std::string tga(18, '\0');
    tga[2] = 2, tga[12] = 2, tga[14] = 2, tga[16] = 24;
    tga += std::string(12, char(200));
    std::ofstream(d / "fuzz.tga", std::ios::binary) << tga;
    return d;
  }();
  static const struct Cleanup {
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup;
  return dir;
}

std::vector<std::string> seeds() {
  std::vector<std::string> out(std::begin(inline_scenes), std::end(inline_scenes));
  for (const char* sub : {"scenes/course", "scenes/stress"}) {
    const fs::path d = fs::path(TUILE_SOURCE_DIR) / sub;
    if (!fs::is_directory(d)) continue;
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(d))
      if (e.path().extension() == ".pbrt" && e.file_size() < 64 * 1024) files.push_back(e.path());
    std::sort(files.begin(), files.end());  // deterministic order
    for (const auto& f : files) {
      std::ifstream in(f, std::ios::binary);
      std::stringstream ss;
      ss << in.rdbuf();
      out.push_back(ss.str());
    }
  }
  return out;
}

std::string mutate(std::string s, std::mt19937& rng) {
  auto pick = [&](size_t n) { return n ? size_t(rng() % n) : 0; };
  static const char* const inserts[] = {"nan",  " inf ", " -inf ", " 1e39 ", " 1e999 ", " 99999999999 ", " -1 ", " 0 ",
                                        " [ ", " ] ",   "\"",     " \"float fov\" ", "AttributeBegin\n",
                                        "AttributeEnd\n", "ObjectEnd\n", " 1e-45 ", " 4294967296 ", "#", "\n",
                                        " \"integer indices\" [ 0 1 7 ] ", " \"point3 P\" [ 1 2 ] ", "WorldBegin\n",
                                        "Include \"fuzz_inc.pbrt\"\n", " \"rgb L\" [ 1e38 1e38 1e38 ] "};
  const int n_mut = 1 + int(rng() % 4);
  for (int m = 0; m < n_mut && !s.empty(); ++m) {
    const size_t at = pick(s.size());
    switch (rng() % 8) {
      case 0: s[at] = char(rng() % 256); break;  // byte flip
      case 1: s.erase(at, 1 + pick(16)); break;  // deletion
      case 2: {                                  // duplicate a token
        size_t b = at;
        while (b < s.size() && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
        size_t e = b;
        while (e < s.size() && !std::isspace(static_cast<unsigned char>(s[e]))) ++e;
        s.insert(pick(s.size()), " " + s.substr(b, e - b) + " ");
        break;
      }
      case 3: s.resize(at); break;  // truncation
      case 4: s.insert(at, inserts[pick(std::size(inserts))]); break;
      case 5: {  // replace a number by a huge or odd one
        size_t b = s.find_first_of("0123456789", at);
        if (b == std::string::npos) break;
        size_t e = s.find_first_not_of("0123456789.e-", b);
        s.replace(b, (e == std::string::npos ? s.size() : e) - b, inserts[pick(8)]);
        break;
      }
      case 6: s.insert(at, std::string(1, "[]\"#"[pick(4)])); break;  // unbalanced bracket or quote
      case 7: {  // swap two lines' worth of text
        const size_t b = pick(s.size()), len = pick(40);
        const std::string piece = s.substr(b, len);
        s.erase(b, piece.size());
        s.insert(pick(s.size() + 1), piece);
        break;
      }
    }
  }
  return s;
}

}  // namespace

TEST(PbrtFuzz, SeedsAreValid) {
  const std::string dir = fuzz_dir().string();
  for (const std::string& s : seeds()) EXPECT_NO_THROW(load_pbrt_string(s, "fuzz.pbrt", dir)) << s.substr(0, 200);
}

TEST(PbrtFuzz, MutationsLoadOrThrowSceneError) {
  const std::string dir = fuzz_dir().string();
  const std::vector<std::string> base = seeds();
  ASSERT_FALSE(base.empty());
  std::mt19937 rng(20240611);
  constexpr int total = 5000;
  // Time bound per input: generous enough for a sanitizer build of a debug library,
  // far below what a hang or an exponential blow-up would take.
  constexpr double bound_s = 2.0;
  int loaded = 0, rejected = 0, slow = 0;
  double worst = 0;
  for (int i = 0; i < total; ++i) {
    const std::string input = mutate(base[size_t(i) % base.size()], rng);
    const auto t0 = std::chrono::steady_clock::now();
    try {
      load_pbrt_string(input, "fuzz.pbrt", dir);
      ++loaded;
    } catch (const SceneError& e) {
      ++rejected;
      const std::string w = e.what();
      // names the scene or a file it includes
      EXPECT_TRUE(w.rfind("fuzz.pbrt:", 0) == 0 || w.rfind(dir, 0) == 0) << w;
      EXPECT_NE(w.find(": error: "), std::string::npos) << w;
      EXPECT_NE(w.find("(expected "), std::string::npos) << w;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "mutation " << i << " threw a non-SceneError: " << e.what() << "\ninput:\n" << input;
    }
    const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    worst = std::max(worst, dt);
    if (dt > bound_s) {
      ++slow;
      ADD_FAILURE() << "mutation " << i << " took " << dt << " s";
    }
  }
  EXPECT_EQ(slow, 0);
  EXPECT_GT(loaded, 0);
  EXPECT_GT(rejected, total / 10);
  std::printf("  %d mutations: %d loaded, %d rejected with SceneError, slowest %.1f ms\n", total, loaded, rejected, 1e3 * worst);
}

TEST(PbrtFuzz, DamagedPlyFilesThrowSceneError) {
  const fs::path dir = fuzz_dir();
  std::ifstream ascii_in(dir / "fuzz_ascii.ply");
  std::stringstream ss;
  ss << ascii_in.rdbuf();
  const std::string bases[] = {fuzz_ply(), ss.str()};
  static const char* const header_edits[][2] = {
      {"element vertex 4", "element vertex 4000000000"}, {"element vertex 3", "element vertex 99"},
      {"element face 2", "element face 2000000000"},     {"uchar int", "int int"},
      {"uchar int", "uchar float"},                      {"property float z\n", ""},
      {"binary_little_endian", "binary_big_endian"},     {"end_header", "end_headr"},
      {"format ascii", "format binary_little_endian"},   {"vertex_indices", "vertex_indexes"}};
  std::mt19937 rng(7);
  int loaded = 0, rejected = 0;
  for (int i = 0; i < 1000; ++i) {
    std::string ply = bases[i % 2];
    const int kind = int(rng() % 4);
    if (kind == 0) {
      const auto& e = header_edits[rng() % std::size(header_edits)];
      const size_t at = ply.find(e[0]);
      if (at != std::string::npos) ply.replace(at, std::strlen(e[0]), e[1]);
    } else if (kind == 1) {
      ply.resize(rng() % ply.size());
    } else {
      for (int k = 0; k < 1 + int(rng() % 3); ++k) ply[rng() % ply.size()] = char(rng() % 256);
    }
    std::ofstream(dir / "damaged.ply", std::ios::binary) << ply;
    try {
      load_pbrt_string("WorldBegin\nAreaLightSource \"diffuse\"\nShape \"plymesh\" \"string filename\" \"damaged.ply\"\n", "fuzz.pbrt",
                       dir.string());
      ++loaded;
    } catch (const SceneError& e) {
      ++rejected;
      EXPECT_EQ(std::string(e.what()).rfind("fuzz.pbrt:3:1: error: ", 0), 0u) << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << "PLY mutation " << i << " threw a non-SceneError: " << e.what();
    }
  }
  EXPECT_GT(loaded, 0);
  EXPECT_GT(rejected, 0);
  std::printf("  1000 damaged PLY files: %d loaded, %d rejected with SceneError\n", loaded, rejected);
}
