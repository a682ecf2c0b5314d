// The measurement instruments: error metrics with known answers, `tuile converge`'s CSV
// and SVG plot, and `tuile figures --quick`'s PNG contact sheets.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "app/cli.h"
#include "app/commands.h"
#include "accel/embree.h"
#include "scene/image_io.h"
#include "measure/metrics.h"
#include "measure/plot.h"
#include "render/render.h"

namespace fs = std::filesystem;
using namespace tuile;

namespace {

fs::path scratch_root() { return fs::temp_directory_path() / ("tuile_test_measure_" + std::to_string(::getpid())); }

// Removes this process's scratch files when the tests end.
struct ScratchCleanup : testing::Environment {
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(scratch_root(), ec);
  }
};
[[maybe_unused]] testing::Environment* const scratch_cleanup = testing::AddGlobalTestEnvironment(new ScratchCleanup);

fs::path scratch_dir(const std::string& name) {
  const fs::path d = scratch_root() / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream in(s);
  while (std::getline(in, cur, sep)) out.push_back(cur);
  return out;
}

bool is_number(const std::string& s, double& v) {
  if (s.empty()) return false;
  char* end = nullptr;
  v = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size();
}

// A reference for two-panels at 32 x 24, rendered once per test binary run.
const fs::path& reference_exr() {
  static const fs::path path = [] {
    const fs::path d = scratch_dir("reference");
    RenderFlags f;
    f.scene = "built-in:two-panels";
    f.res = "32x24";
    f.seed = 777;
    Scene scene = load_scene(f.scene);
    RenderOptions o = resolve_options(f, scene);
    Accel accel(scene);
    Renderer r(scene, accel, o);
    Film film;
    film.reset(scene.camera.width, scene.camera.height);
    r.render(film, 0, 1024);
    const fs::path p = d / "ref.exr";
    write_exr(p.string(), film.width, film.height, film.mean());
    return p;
  }();
  return path;
}

}  // namespace

TEST(Metrics, ConstantImagesHaveClosedForms) {
  const std::vector<float> x(4 * 3, 0.5f), ref(4 * 3, 0.25f);
  EXPECT_DOUBLE_EQ(mse(x, ref), 0.0625);
  EXPECT_NEAR(relmse(x, ref), 0.0625 / (0.0625 + 0.01), 1e-12);
  EXPECT_NEAR(relmse(x, ref, 0.0), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(mse(ref, ref), 0.0);
  EXPECT_DOUBLE_EQ(relmse(ref, ref), 0.0);
  // against a black reference relMSE is MSE / eps
  const std::vector<float> black(12, 0.f);
  EXPECT_NEAR(relmse(x, black), 0.25 / 0.01, 1e-9);
}

TEST(Metrics, MixedPixelsAverageOverPixelsAndChannels) {
  const std::vector<float> x = {1, 2, 3, 0, 0, 0}, ref = {1, 1, 1, 0, 0, 1};
  EXPECT_NEAR(mse(x, ref), (0 + 1 + 4 + 0 + 0 + 1) / 6.0, 1e-12);
  EXPECT_NEAR(relmse(x, ref), (0 + 1 / 1.01 + 4 / 1.01 + 0 + 0 + 1 / 1.01) / 6.0, 1e-12);
  EXPECT_THROW(mse(x, std::vector<float>(3, 0.f)), std::invalid_argument);
  EXPECT_THROW(relmse({}, {}), std::invalid_argument);
}

TEST(Metrics, EfficiencyIsInverseOfRelmseTimesTime) {
  EXPECT_DOUBLE_EQ(efficiency(0.5, 4.0), 0.5);
  EXPECT_DOUBLE_EQ(efficiency(1e-3, 2.0), 500.0);
  EXPECT_TRUE(std::isinf(efficiency(0.0, 1.0)));
  EXPECT_TRUE(std::isnan(efficiency(-1.0, 1.0)));
}

TEST(Metrics, LogLogSlopeAndInterpolation) {
  std::vector<double> t, e, r;
  for (int k = 0; k < 8; ++k) {
    t.push_back(std::ldexp(1.0, k));
    e.push_back(3.0 / t.back());
    r.push_back(2.0 / std::sqrt(t.back()));
  }
  EXPECT_NEAR(loglog_slope(t, e), -1.0, 1e-12);
  EXPECT_NEAR(loglog_slope(t, r), -0.5, 1e-12);
  EXPECT_TRUE(std::isnan(loglog_slope({1.0}, {1.0})));
  EXPECT_NEAR(loglog_interpolate(t, e, 3.0), 1.0, 1e-12);  // exact for a power law
  EXPECT_NEAR(loglog_interpolate(t, e, 1.0), 3.0, 1e-12);
  EXPECT_TRUE(std::isnan(loglog_interpolate(t, e, 0.5)));
  EXPECT_TRUE(std::isnan(loglog_interpolate(t, e, 1000.0)));
}

// The .npy files the figures hand to matplotlib: NumPy's format 1.0 header (magic,
// version, a 64-byte aligned dict ending in a newline) and the floats after it.
TEST(Plot, NpyFilesFollowNumpysFormat) {
  const fs::path d = scratch_dir("npy");
  const std::vector<float> v = {0.f, 1.f, -2.5f, 3.f, 4.f, 5.f};
  write_npy((d / "a.npy").string(), {1, 2, 3}, v.data());
  const std::string s = slurp(d / "a.npy");
  ASSERT_GE(s.size(), 10u);
  EXPECT_EQ(s.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
  const size_t hl = static_cast<uint8_t>(s[8]) | (static_cast<size_t>(static_cast<uint8_t>(s[9])) << 8);
  EXPECT_EQ((10 + hl) % 64, 0u);
  const std::string dict = s.substr(10, hl);
  EXPECT_NE(dict.find("'descr': '<f4'"), std::string::npos) << dict;
  EXPECT_NE(dict.find("'shape': (1, 2, 3)"), std::string::npos) << dict;
  EXPECT_EQ(dict.back(), '\n');
  ASSERT_EQ(s.size(), 10 + hl + v.size() * 4);
  float back[6];
  std::memcpy(back, s.data() + 10 + hl, sizeof back);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(back[i], v[static_cast<size_t>(i)]);
}

// Without an interpreter to draw with, the error says what to install and how to point
// tuile at another python3.
TEST(Plot, MissingPythonIsAClearError) {
  const fs::path d = scratch_dir("nopython");
  setenv("TUILE_PYTHON", (d / "no-such-python3").c_str(), 1);
  Plot p;
  p.output = (d / "p.png").string();
  p.series.push_back(PlotSeries{"s", {1, 2}, {1, 0.5}});
  try {
    draw_with_matplotlib({p}, {});
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("TUILE_PYTHON"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("python3-matplotlib"), std::string::npos) << e.what();
  }
  unsetenv("TUILE_PYTHON");
  EXPECT_FALSE(fs::exists(p.output));
}

TEST(Converge, CsvSchemaAndSppDoubling) {
  const fs::path d = scratch_dir("converge");
  ConvergeFlags f;
  f.render.scene = "built-in:two-panels";
  f.render.res = "32x24";
  f.render.quiet = true;
  f.reference = reference_exr().string();
  f.strategies = "light:area,bsdf,mis:power";
  f.budget = 0.5;
  f.spp_max = 64;
  f.csv = (d / "c.csv").string();
  f.plot = (d / "c.svg").string();
  ASSERT_EQ(run_converge(f), 0);

  const std::vector<std::string> lines = split(slurp(f.csv), '\n');
  ASSERT_GE(lines.size(), 4u);
  EXPECT_EQ(lines[0], "strategy,spp,seconds,mse,relmse,efficiency");
  std::map<std::string, std::vector<double>> spp, secs;
  for (size_t i = 1; i < lines.size(); ++i) {
    if (lines[i].empty()) continue;
    const std::vector<std::string> fields = split(lines[i], ',');
    ASSERT_EQ(fields.size(), 6u) << lines[i];
    double v[5];
    for (int k = 0; k < 5; ++k) ASSERT_TRUE(is_number(fields[k + 1], v[k])) << lines[i];
    EXPECT_GT(v[1], 0);   // seconds
    EXPECT_GE(v[2], 0);   // mse
    EXPECT_GE(v[3], 0);   // relmse
    EXPECT_NEAR(v[4], 1 / (v[3] * v[1]), 1e-6 * v[4]);  // efficiency
    spp[fields[0]].push_back(v[0]);
    secs[fields[0]].push_back(v[1]);
  }
  ASSERT_EQ(spp.size(), 3u);
  for (const auto& [name, s] : spp) {
    ASSERT_GE(s.size(), 2u) << name;
    EXPECT_EQ(s[0], 1) << name;
    for (size_t i = 1; i < s.size(); ++i) {
      EXPECT_EQ(s[i], 2 * s[i - 1]) << name;
      EXPECT_GE(secs[name][i], secs[name][i - 1]) << name;  // cumulative
    }
    EXPECT_LE(s.back(), 64) << name;
  }

  // drawn by matplotlib, its text kept as text: one legend entry per strategy
  const std::string svg = slurp(f.plot);
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  for (const char* name : {"light:area", "bsdf", "mis:power", "1/t"}) EXPECT_NE(svg.find(name), std::string::npos) << name;
}

// The many-lights strategies (#19) run under converge: each gets its rows, and its error
// falls with samples (relMSE at the last doubling well under the first's). The budget is
// far beyond need and spp_max ends every strategy at 16 spp, so the rows do not depend on
// the machine's speed (a sanitizer build is ten times slower).
TEST(Converge, ManyLightStrategies) {
  const fs::path d = scratch_dir("converge-many");
  ConvergeFlags f;
  f.render.scene = "built-in:two-panels";
  f.render.res = "32x24";
  f.render.quiet = true;
  f.reference = reference_exr().string();
  f.strategies = "light:bvh,mis:bvh,ris,ris:power";
  f.budget = 600;
  f.spp_max = 16;
  f.csv = (d / "m.csv").string();
  ASSERT_EQ(run_converge(f), 0);
  std::map<std::string, std::vector<double>> rel;
  const std::vector<std::string> lines = split(slurp(f.csv), '\n');
  for (size_t i = 1; i < lines.size(); ++i) {
    if (lines[i].empty()) continue;
    const std::vector<std::string> fields = split(lines[i], ',');
    ASSERT_EQ(fields.size(), 6u) << lines[i];
    double v = 0;
    ASSERT_TRUE(is_number(fields[4], v)) << lines[i];
    rel[fields[0]].push_back(v);
  }
  ASSERT_EQ(rel.size(), 4u);
  for (const auto& [name, r] : rel) {
    ASSERT_EQ(r.size(), 5u) << name;  // 1, 2, 4, 8, 16 spp
    EXPECT_LT(r.back(), 0.5 * r.front()) << name;
  }
}

TEST(Converge, RendersAndSavesAReferenceWhenNoneIsGiven) {
  const fs::path d = scratch_dir("converge-noref");
  ConvergeFlags f;
  f.render.scene = "built-in:two-panels";
  f.render.res = "32x24";
  f.render.quiet = true;
  f.strategies = "mis:balance";
  f.budget = 0.2;
  f.spp_max = 8;
  f.reference_spp = 64;
  f.csv = (d / "run.csv").string();
  f.plot = (d / "run.png").string();
  ASSERT_EQ(run_converge(f), 0);
  int w = 0, h = 0;
  const std::vector<float> ref = read_exr((d / "run-reference.exr").string(), w, h);
  EXPECT_EQ(w, 32);
  EXPECT_EQ(h, 24);
  EXPECT_EQ(slurp(f.plot).substr(1, 3), "PNG");
}

TEST(Converge, RejectsBadArguments) {
  ConvergeFlags f;
  f.render.res = "32x24";
  f.render.quiet = true;
  f.reference = reference_exr().string();
  f.strategies = "light:nonsense";
  EXPECT_THROW(run_converge(f), std::invalid_argument);
  f.strategies = "bsdf";
  f.render.res = "16x16";  // the reference is 32 x 24
  EXPECT_THROW(run_converge(f), std::invalid_argument);
  f.render.res = "32x24";
  f.budget = 0;
  EXPECT_THROW(run_converge(f), std::invalid_argument);
  f.budget = 1;
  f.plot = "x.gif";
  EXPECT_THROW(run_converge(f), std::invalid_argument);
}

TEST(Figures, QuickRunWritesTheContactSheets) {
  const fs::path d = scratch_dir("figures");
  FiguresFlags f;
  f.out = d.string();
  f.quick = true;
  ASSERT_EQ(run_figures(f), 0);
  for (const char* name : {"a-noise.png", "b-points-per-source.png", "c-light-pdfs.png", "d-mis.png", "e-warmup.png",
                           "f-veach-plates.png", "g-optimal-mis.png"}) {
    const std::string png = slurp(d / name);
    ASSERT_GE(png.size(), 33u) << name;
    EXPECT_EQ(png.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8)) << name;
    EXPECT_EQ(png.substr(12, 4), "IHDR") << name;
    auto be32 = [&](size_t at) {
      return (uint32_t(uint8_t(png[at])) << 24) | (uint32_t(uint8_t(png[at + 1])) << 16) |
             (uint32_t(uint8_t(png[at + 2])) << 8) | uint32_t(uint8_t(png[at + 3]));
    };
    const uint32_t w = be32(16), h = be32(20);
    EXPECT_GE(w, 40u) << name;
    EXPECT_GE(h, 30u) << name;
    EXPECT_LE(w, 2000u) << name;
    EXPECT_LE(h, 2000u) << name;
  }
  const std::string svg = slurp(d / "e-warmup.svg");
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  for (const char* series : {"U[-1,1]", "U[-10,10]", "1% in U[-10,10]", "1/sqrt(N)"})
    EXPECT_NE(svg.find(series), std::string::npos) << series;
}
