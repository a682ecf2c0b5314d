// Rendering over MPI ranks, run for real with mpirun (--oversubscribe, and
// --allow-run-as-root where the tests run as root): K = 1 to 4 ranks give the bytes of the
// single-process render, guided renders too; a scene that fails to load is reported once; a rank that exits,
// or stops answering, ends the job with a message naming it, within the timeout, and rank
// 0 writes the complete passes it has. Skipped with a message where tuile was built
// without MPI or mpirun is missing.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "render/checkpoint.h"
#include "render/passes.h"
#include "output_files.h"
#include "scene/image_io.h"

using namespace tuile;
using tuile::testing::same_pixels;
using tuile::testing::TempDir;
namespace fs = std::filesystem;

namespace {

#ifdef TUILE_MPIEXEC
const char* kMpiexec = TUILE_MPIEXEC;
#else
const char* kMpiexec = nullptr;
#endif

bool mpi_ready(std::string& why) {
  if (!kMpiexec) {
    why = "tuile was built without MPI (install libopenmpi-dev and reconfigure)";
    return false;
  }
  if (!fs::exists(kMpiexec)) {
    why = std::string("no ") + kMpiexec;
    return false;
  }
  return true;
}

// Runs a shell command, returns its exit status and its output (stdout and stderr).
int run(const std::string& cmd, std::string& out) {
  FILE* f = popen((cmd + " 2>&1").c_str(), "r");
  if (!f) return -1;
  char buf[4096];
  out.clear();
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), f)) > 0) out.append(buf, n);
  const int status = pclose(f);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string mpirun(int ranks, const std::string& env = "") {
  std::string cmd = env + " " + kMpiexec + " --oversubscribe";
  if (geteuid() == 0) cmd += " --allow-run-as-root";
  for (const char* var : {"TUILE_TEST_FAIL_RANK", "TUILE_TEST_FAIL_MODE"})
    if (env.find(var) != std::string::npos) cmd += std::string(" -x ") + var;
  return cmd + " -n " + std::to_string(ranks) + " " + TUILE_BINARY;
}

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

}  // namespace

TEST(Mpi, AnyNumberOfRanksGivesTheSingleProcessBytes) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  // 96x64: passes of 1365 spp (2^23 samples), so one more is two passes of unequal size, the
  // second of one sample per pixel. (3000 spp, three passes, took 53 s natively, 72 s in the
  // portable tree: the renders' cost is the passes' 2^23 samples each, whatever the image.)
  const uint32_t spp = fixed_passes(96 * 64).pass_spp + 1;
  const std::string course = std::string(TUILE_SOURCE_DIR) + "/scenes/course/noise-room.pbrt";
  for (const std::string& scene : {std::string("built-in:cornell"), std::string("built-in:two-panels"), course}) {
    const std::string args = " render " + scene + " --res 96x64 --spp " + std::to_string(spp) + " --quiet -o ";
    std::string out;
    ASSERT_EQ(run(std::string(TUILE_BINARY) + args + (dir / "one.exr"), out), 0) << out;
    for (int k = 1; k <= 4; ++k) {
      const std::string exr = dir / ("k" + std::to_string(k) + ".exr");
      ASSERT_EQ(run(mpirun(k) + args + exr, out), 0) << scene << " with " << k << " ranks: " << out;
      EXPECT_TRUE(same_pixels(dir / "one.exr", exr)) << scene << " with " << k << " ranks";
      const int* got = read_exr_metadata(exr).find_integer("spp");
      ASSERT_NE(got, nullptr);
      EXPECT_EQ(static_cast<uint32_t>(*got), spp);
    }
  }
}

// --guide: the ranks sum their records after each of the guide's learning iterations, so a
// guided render has the single process's bytes: one whose iterations all fall in its first
// pass (several steps of one pass, added as one process adds them), and one resumed from a
// single process's checkpoint in the middle of an iteration (its first units render the
// learning samples again; the iteration [16, 32) then ends with records of both kinds).
TEST(Mpi, GuidedRendersGiveTheSingleProcessBytes) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  const std::string args = " render built-in:cornell --res 96x64 --max-depth 4 --guide --guide-learn 32 --quiet ";
  std::string out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + args + "--spp 40 -o " + (dir / "one.exr"), out), 0) << out;
  for (int k = 2; k <= 3; ++k) {
    const std::string exr = dir / ("k" + std::to_string(k) + ".exr");
    ASSERT_EQ(run(mpirun(k) + args + "--spp 40 -o " + exr, out), 0) << k << " ranks: " << out;
    EXPECT_TRUE(same_pixels(dir / "one.exr", exr)) << k << " ranks";
  }
  // the guide changed the image (it is used, not only learned)
  ASSERT_EQ(run(std::string(TUILE_BINARY) + " render built-in:cornell --res 96x64 --max-depth 4 --quiet --spp 40 -o " +
                    (dir / "plain.exr"),
                out),
            0)
      << out;
  EXPECT_FALSE(same_pixels(dir / "one.exr", dir / "plain.exr"));
  // resumed at sample 20, inside the iteration [16, 32): in one process and over three ranks
  for (const std::string name : {"resumed-one", "resumed-mpi"}) {
    const std::string exr = dir / (name + ".exr");
    ASSERT_EQ(run(std::string(TUILE_BINARY) + args + "--spp 20 --checkpoint 1000 -o " + exr, out), 0) << out;
    const std::string launch = name == "resumed-one" ? std::string(TUILE_BINARY) : mpirun(3);
    ASSERT_EQ(run(launch + args + "--spp 40 --resume -o " + exr, out), 0) << name << ": " << out;
    const int* got = read_exr_metadata(exr).find_integer("spp");
    ASSERT_NE(got, nullptr);
    EXPECT_EQ(*got, 40);
  }
  EXPECT_TRUE(same_pixels(dir / "resumed-one.exr", dir / "resumed-mpi.exr"));
}

// --bdpt under mpirun (auto: the file asks for pbrt's bdpt): every contribution is a splat,
// so the sample ranges are light chunks (as --light-paths'), traced on any rank and added by
// rank 0 in the single process's order: the job renders the single process's bytes (a
// scene with a sky, a sun and a medium).
TEST(Mpi, BdptRendersTheSingleProcessBits) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  const std::string scene = dir / "bdpt.pbrt";
  std::ofstream(scene) << "LookAt 0 1.2 4  0 0.4 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 45 ]\n"
                          "Integrator \"bdpt\" \"integer maxdepth\" [ 4 ]\nWorldBegin\n"
                          "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [ 8 8 8 ]\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -0.5 2 -0.5  0.5 2 -0.5  0.5 2 0.5  -0.5 2 0.5 ] "
                          "\"integer indices\" [ 0 1 2  0 2 3 ]\nAttributeEnd\n"
                          "Material \"diffuse\" \"rgb reflectance\" [ 0.6 0.6 0.6 ]\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -3 0 -3  3 0 -3  3 0 3  -3 0 3 ] "
                          "\"integer indices\" [ 0 2 1  0 3 2 ]\n"
                          "Material \"dielectric\" \"float eta\" [ 1.5 ]\n"  // (a glass ball full of a fog: media too)
                          "MakeNamedMedium \"fog\" \"string type\" \"homogeneous\" \"rgb sigma_a\" [ 0.2 0.3 0.4 ] "
                          "\"rgb sigma_s\" [ 1 1 1 ] \"float scale\" [ 1 ]\n"
                          "AttributeBegin\nMediumInterface \"fog\" \"\"\nTranslate 0 0.5 0\nShape \"sphere\" \"float radius\" [ 0.5 ]\n"
                          "AttributeEnd\n"
                          "LightSource \"infinite\" \"rgb L\" [ 0.1 0.12 0.15 ]\n"  // (a sky and a sun: bdpt's too)
                          "LightSource \"distant\" \"point3 from\" [ 1 3 2 ] \"point3 to\" [ 0 0 0 ] \"rgb L\" [ 0.5 0.5 0.5 ]\n";
  const std::string args = " render " + scene + " --res 128x64 --spp 6 --quiet -o ";
  std::string out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + args + (dir / "auto.exr"), out), 0) << out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + args + (dir / "off.exr") + " --bdpt=off", out), 0) << out;
  EXPECT_FALSE(same_pixels(dir / "auto.exr", dir / "off.exr"));  // bdpt rendered it
  ASSERT_EQ(run(mpirun(3) + args + (dir / "mpi.exr"), out), 0) << out;
  EXPECT_TRUE(same_pixels(dir / "auto.exr", dir / "mpi.exr"));
}

// --light-paths under mpirun: a light path lands anywhere in the image, so the light paths
// are units of their own (chunks of about 2^22 paths, the whole image's sums each), which
// rank 0 adds to each pass in the single process's order: the job renders the single
// process's bytes, here where auto turns them on (a sun and a metal ball of alpha 0.05), at
// a size where a pass holds two chunks and the last pass one. With --guide too, whose
// learning iterations cut the first pass into steps, each with its own light chunk: rank 0
// adds each step's camera sums and then its chunks, as the single process does.
TEST(Mpi, LightPathsRenderTheSingleProcessBits) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  const std::string scene = dir / "sun.pbrt";
  std::ofstream(scene) << "LookAt 0 1.2 4  0 0.4 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 45 ]\n"
                          "Integrator \"path\" \"integer maxdepth\" [ 5 ]\nWorldBegin\n"
                          "LightSource \"distant\" \"point3 from\" [ 0 4 -3 ] \"point3 to\" [ 0 0 0 ] \"rgb L\" [ 3 3 3 ]\n"
                          "Material \"diffuse\" \"rgb reflectance\" [ 0.6 0.6 0.6 ]\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -3 0 -3  3 0 -3  3 0 3  -3 0 3 ] "
                          "\"integer indices\" [ 0 2 1  0 3 2 ]\n"
                          "Material \"conductor\" \"float roughness\" [ 0.05 ] \"bool remaproughness\" false\n"
                          "AttributeBegin\nTranslate 0 0.5 0\nShape \"sphere\" \"float radius\" [ 0.5 ]\nAttributeEnd\n";
  const int w = 512, h = 256;
  const uint32_t pass = fixed_passes(static_cast<uint64_t>(w) * h).pass_spp;
  const uint32_t chunk = std::max<uint32_t>(1, (1u << 22) / (w * h));  // (Renderer::light_chunk_samples)
  ASSERT_GT(pass, chunk);
  const uint32_t spp = pass + chunk / 2;  // (a second pass of part of a chunk)
  const std::string args = " render " + scene + " --res " + std::to_string(w) + "x" + std::to_string(h) + " --spp " +
                           std::to_string(spp) + " --quiet -o ";
  std::string out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + args + (dir / "auto.exr"), out), 0) << out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + args + (dir / "off.exr") + " --light-paths=off", out), 0) << out;
  EXPECT_FALSE(same_pixels(dir / "auto.exr", dir / "off.exr"));  // on in one process
  ASSERT_EQ(run(mpirun(3) + args + (dir / "mpi.exr"), out), 0) << out;
  EXPECT_TRUE(same_pixels(dir / "auto.exr", dir / "mpi.exr"));
  // (the checkpoints hold the film's double sums and squares too, which the image does not
  // show; at these few samples a sum of floats is exact in double whatever the order, so
  // the order rank 0 adds a pass's parts in is held by construction, not by this test)
  const std::string guided =
      " render " + scene + " --res 128x64 --spp 24 --guide --guide-learn 4 --checkpoint 1000 --quiet -o ";
  ASSERT_EQ(run(std::string(TUILE_BINARY) + guided + (dir / "guided.exr") + " --light-paths", out), 0) << out;
  ASSERT_EQ(run(std::string(TUILE_BINARY) + guided + (dir / "guided-off.exr") + " --light-paths=off", out), 0) << out;
  EXPECT_FALSE(same_pixels(dir / "guided.exr", dir / "guided-off.exr"));
  ASSERT_EQ(run(mpirun(3) + guided + (dir / "guided-mpi.exr") + " --light-paths", out), 0) << out;
  EXPECT_TRUE(same_pixels(dir / "guided.exr", dir / "guided-mpi.exr"));
  auto bytes = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string one = bytes(checkpoint_path(dir / "guided.exr")), mpi = bytes(checkpoint_path(dir / "guided-mpi.exr"));
  ASSERT_FALSE(one.empty());
  EXPECT_TRUE(one == mpi) << "the checkpoints' film sums differ";
}

TEST(Mpi, AMissingSceneIsReportedOnce) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  std::string out;
  EXPECT_NE(run(mpirun(3) + " render " + (dir / "missing.pbrt") + " -o " + (dir / "x.exr"), out), 0);
  EXPECT_EQ(count(out, "missing.pbrt"), 1u) << out;
  EXPECT_NE(out.find("3 of 3 ranks failed"), std::string::npos) << out;
}

TEST(Mpi, ARankThatExitsEndsTheJobAndRankZeroKeepsWhatItHas) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  std::string out;
  const auto t0 = std::chrono::steady_clock::now();
  const std::string exr = dir / "f.exr";
  // rank 2 exits after 13 units (a pass is 6 here: its first pass is complete by then)
  EXPECT_NE(run(mpirun(3, "TUILE_TEST_FAIL_RANK=2 TUILE_TEST_FAIL_AFTER=13") + " render built-in:cornell --res 96x64 --spp 20000 -o " + exr,
                out),
            0);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 60.0);
  // mpirun names the process that failed (job id, rank 2) and its exit code
  EXPECT_NE(out.find(",2]"), std::string::npos) << out;
  ASSERT_TRUE(fs::exists(exr)) << out;
  const ExrMetadata m = read_exr_metadata(exr);
  ASSERT_NE(m.find_integer("spp"), nullptr);
  EXPECT_GT(*m.find_integer("spp"), 0) << "rank 0 keeps the passes it has";
  EXPECT_EQ(*m.find_integer("spp") % static_cast<int>(fixed_passes(96 * 64).pass_spp), 0) << "complete passes only";
  // a rank that fails before the first pass is complete: nothing is written (there is nothing
  // to keep, and an earlier render's image of that name stays as it was)
  const std::string before = std::string(std::istreambuf_iterator<char>(std::ifstream(exr, std::ios::binary).rdbuf()), {});
  EXPECT_NE(run(mpirun(3, "TUILE_TEST_FAIL_RANK=2") + " render built-in:cornell --res 96x64 --spp 20000 -o " + exr, out), 0);
  EXPECT_NE(out.find("nothing written"), std::string::npos) << out;
  EXPECT_TRUE(std::string(std::istreambuf_iterator<char>(std::ifstream(exr, std::ios::binary).rdbuf()), {}) == before);
}

TEST(Mpi, ARankThatStopsAnsweringEndsTheJobWithinTheTimeout) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  TempDir dir;
  std::string out;
  const auto t0 = std::chrono::steady_clock::now();
  const std::string exr = dir / "h.exr";
  EXPECT_NE(run(mpirun(3, "TUILE_TEST_FAIL_RANK=2 TUILE_TEST_FAIL_MODE=hang") +
                    " render built-in:cornell --res 96x64 --spp 20000 --mpi-timeout 2 -o " + exr,
                out),
            0);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 60.0);
  EXPECT_NE(out.find("rank 2 has not answered for 2 s"), std::string::npos) << out;
  // (it stops answering after its first unit: no pass is complete, so nothing is written)
  EXPECT_NE(out.find("nothing written"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(exr)) << out;
}

TEST(Mpi, BenchReportsEveryRankAndTheCommunication) {
  std::string why;
  if (!mpi_ready(why)) GTEST_SKIP() << why;
  std::string out;
  ASSERT_EQ(run(mpirun(3) + " bench built-in:cornell --res 96x64 --spp 64 --repeat 2 --warmup 0", out), 0) << out;
  EXPECT_NE(out.find("total:"), std::string::npos) << out;
  EXPECT_NE(out.find("communication s"), std::string::npos) << out;
  for (const char* rank : {"\n1 ", "\n2 "}) EXPECT_NE(out.find(rank), std::string::npos) << out;
}
