// The many-lights scene generator (scenes/tools/tuile_gen_lights.cpp), run as the built
// executable: N = 1000 loads as exactly 1000 one-sided triangle sources facing into the
// room, their luminances span the requested decades over the requested levels, the power
// is the requested one, the same options give the same bytes, and bad input is an error.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>

#include "output_files.h"
#include "scene/scene.h"

namespace fs = std::filesystem;

namespace {

using tuile::testing::CmdResult;
CmdResult gen(const std::string& args) { return tuile::testing::run_command(TUILE_GEN_LIGHTS, args); }

std::string tmp(const std::string& name) {
  const fs::path p = fs::path(::testing::TempDir()) / name;
  fs::remove_all(p);
  return p.string();
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

double luminance_d(const tuile::Rgb& c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; }

}  // namespace

TEST(GenLights, ThousandOneSidedSourcesFacingIn) {
  const std::string dir = tmp("gen_lights_1000");
  const CmdResult r = gen("--out " + dir + " --emitters 1000 --decades 3 --levels 40 --seed 7 --power 900");
  ASSERT_EQ(r.code, 0) << r.out;
  const tuile::Scene s = tuile::load_scene(dir + "/scene.pbrt");
  ASSERT_EQ(s.lights.size(), 1000u);
  EXPECT_EQ(s.file_max_depth, 1);
  EXPECT_EQ(s.camera.width, 256);
  EXPECT_EQ(s.camera.height, 192);

  const double cx = 0, cy = 1.5, cz = 0;  // the room's centre
  double lo = 1e300, hi = 0, power = 0;
  std::set<float> levels;
  size_t emissive_meshes = 0;
  for (const tuile::Mesh& m : s.meshes) emissive_meshes += m.emissive();
  EXPECT_EQ(emissive_meshes, 40u);
  for (const tuile::Light& l : s.lights) {
    ASSERT_EQ(l.type, tuile::LightKind::triangle);
    EXPECT_FALSE(l.two_sided);
    EXPECT_GT(l.area, 0.f);
    // emission side: cross(e1, e2); the centre must be strictly in front
    const double nx = double(l.e1.y) * l.e2.z - double(l.e1.z) * l.e2.y;
    const double ny = double(l.e1.z) * l.e2.x - double(l.e1.x) * l.e2.z;
    const double nz = double(l.e1.x) * l.e2.y - double(l.e1.y) * l.e2.x;
    const double nl = std::sqrt(nx * nx + ny * ny + nz * nz);
    const double dx = cx - l.p0.x, dy = cy - l.p0.y, dz = cz - l.p0.z;
    EXPECT_GT((nx * dx + ny * dy + nz * dz) / nl, 1e-3) << "light at " << l.p0.x << " " << l.p0.y << " " << l.p0.z;
    // inside the 8 x 3 x 12 m room
    for (const auto& p : {l.p0, l.p0 + l.e1, l.p0 + l.e2}) {
      EXPECT_TRUE(p.x > -4 && p.x < 4 && p.y > 0 && p.y < 3 && p.z > -6 && p.z < 6);
    }
    const double y = luminance_d(l.radiance);
    lo = std::min(lo, y);
    hi = std::max(hi, y);
    power += l.power;
    levels.insert(float(y));
  }
  EXPECT_NEAR(hi / lo, 1e3, 1e3 * 1e-4);
  EXPECT_EQ(levels.size(), 40u);
  EXPECT_NEAR(power, 900, 900 * 1e-3);
  // sizes vary by about 10x
  float amin = 1e30f, amax = 0;
  for (const tuile::Light& l : s.lights) amin = std::min(amin, l.area), amax = std::max(amax, l.area);
  EXPECT_GT(amax / amin, 30.f);  // area ratio: about 100 for a size ratio of 10

  // the same options give the same bytes; another seed does not
  const std::string again = tmp("gen_lights_1000_again"), other = tmp("gen_lights_1000_seed8");
  ASSERT_EQ(gen("--out " + again + " --emitters 1000 --decades 3 --levels 40 --seed 7 --power 900").code, 0);
  ASSERT_EQ(gen("--out " + other + " --emitters 1000 --decades 3 --levels 40 --seed 8 --power 900").code, 0);
  for (const char* f : {"scene.pbrt", "models/emitters_000.ply", "models/emitters_039.ply"})
    EXPECT_EQ(slurp(fs::path(dir) / f), slurp(fs::path(again) / f)) << f;
  EXPECT_NE(slurp(fs::path(dir) / "models/emitters_000.ply"), slurp(fs::path(other) / "models/emitters_000.ply"));
}

TEST(GenLights, CheckReportsTheExactCount) {
  const std::string dir = tmp("gen_lights_check");
  const CmdResult r = gen("--out " + dir + " --emitters 1000 --check");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("loaded 1000 lights (64 emissive meshes"), std::string::npos) << r.out;
  // fewer emitters than levels: one level per emitter
  const CmdResult small = gen("--out " + tmp("gen_lights_small") + " --emitters 5 --check");
  ASSERT_EQ(small.code, 0) << small.out;
  EXPECT_NE(small.out.find("loaded 5 lights (5 emissive meshes"), std::string::npos) << small.out;
}

TEST(GenLights, BadInputIsAClearError) {
  const std::string dir = tmp("gen_lights_bad");
  for (const char* args : {"--emitters 0", "--emitters -5", "--emitters 10000001", "--emitters abc", "--emitters 12x",
                           "--emitters 1e3", "--emitters", "--emitters 10 --decades nan", "--emitters 10 --decades -1",
                           "--emitters 10 --seed -1", "--emitters 10 --res 256", "--emitters 10 --levels 0",
                           "--emitters 10 --max-depth 0", "--emitters 10 --frobnicate", "--emitters 10 --view up"}) {
    const CmdResult r = gen("--out " + dir + " " + args);
    EXPECT_NE(r.code, 0) << args;
    EXPECT_NE(r.out.find("tuile_gen_lights: "), std::string::npos) << args << ": " << r.out;
    EXPECT_FALSE(fs::exists(fs::path(dir) / "scene.pbrt")) << args;
  }
  CmdResult r = gen("--emitters 10");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("--out"), std::string::npos) << r.out;
  // a directory that cannot be made: a path below a regular file
  const std::string file = tmp("gen_lights_file");
  std::ofstream(file) << "x";
  r = gen("--out " + file + "/sub --emitters 10");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("cannot create"), std::string::npos) << r.out;
}
