// The command-line contract: subcommands, --help/--version, exit codes and messages on bad
// input, the files render writes, and the JSON schema of bench.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <string>

#include "output_files.h"
#include "scene/image_io.h"

namespace fs = std::filesystem;

namespace {
using tuile::testing::CmdResult;
CmdResult run(const std::string& args) { return tuile::testing::run_command(TUILE_BINARY, args); }
std::string tmp(const std::string& name) { return (fs::path(::testing::TempDir()) / name).string(); }
}  // namespace

TEST(Cli, HelpAndVersion) {
  for (const char* sub : {"", "render ", "info ", "bench ", "profile ", "converge ", "figures "}) {
    const CmdResult r = run(std::string(sub) + "--help");
    EXPECT_EQ(r.code, 0) << sub;
    EXPECT_NE(r.out.find("--"), std::string::npos) << sub;
  }
  const CmdResult v = run("--version");
  EXPECT_EQ(v.code, 0);
  EXPECT_NE(v.out.find("tuile "), std::string::npos);
  EXPECT_NE(run("").code, 0);  // a subcommand is required
}

TEST(Cli, RenderWritesExrAndPng) {
  const std::string exr = tmp("cli_render.exr");
  const CmdResult r = run("render built-in:cornell --res 24x16 --spp 2 --quiet --aov variance,mis_weight -o " + exr);
  ASSERT_EQ(r.code, 0) << r.out;
  int w = 0, h = 0;
  const std::vector<float> rgb = tuile::read_exr(exr, w, h);
  EXPECT_EQ(w, 24);
  EXPECT_EQ(h, 16);
  double sum = 0;
  for (float x : rgb) sum += x;
  EXPECT_GT(sum, 0.0);
  std::ifstream png(tmp("cli_render.png"), std::ios::binary);
  char sig[8] = {};
  png.read(sig, 8);
  EXPECT_EQ(std::string(sig + 1, 3), "PNG");
}

TEST(Cli, BadInputIsAClearErrorWithExitOne) {
  const std::string bad = tmp("cli_bad.pbrt");
  {
    std::ofstream f(bad);
    f << "LookAt 0 0 0  0 0 1  0 1 0\nCamera \"perspective\"\nWorldBegin\nShape \"trianglemesh\" \"point3 P\" [ 0 0 0 1 0 nan ]\n";
  }
  CmdResult r = run("render " + bad + " --quiet -o " + tmp("cli_bad.exr"));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("cli_bad.pbrt:4:"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(tmp("cli_bad.exr")));  // no partial output
  r = run("render /nonexistent/scene.pbrt --quiet");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("/nonexistent/scene.pbrt"), std::string::npos) << r.out;
  // (4294967304x4294967302 wrapped round to 8x6 in a 32-bit parse and rendered)
  for (const char* args : {"--res 0x10", "--res 100000x100000", "--res 4294967304x4294967302", "--res -8x6", "--res 8x6x2",
                           "--res 8 x6", "--mpi-timeout nan", "--beta nan", "--strategy maybe", "--spp 0",
                           "--light-samples 0", "--threads -1", "--aov unknown", "--pipeline fast",
                           "--bounce-rays nearest", "--bvh tiny"}) {
    r = run(std::string("render built-in:cornell --quiet -o ") + tmp("cli_x.exr") + " " + args);
    EXPECT_EQ(r.code, 1) << args << ": " << r.out;
    EXPECT_NE(r.out.find("error"), std::string::npos) << args << ": " << r.out;
  }
}

// --light-paths takes its optional value after a space as well as after '=' (CLI11 alone took
// `--light-paths off` for a stray positional argument), and a word that is no mode stays the
// argument it was; an option given twice says so plainly (CLI11: "At Most 1 required")
TEST(Cli, LightPathsValueAfterASpaceAndAnOptionGivenTwice) {
  const std::string base = "info built-in:cornell --max-depth 3 ";
  for (const char* mode : {"on", "glossy", "off", "auto"}) {
    const CmdResult spaced = run(base + "--light-paths " + mode);
    const CmdResult joined = run(base + "--light-paths=" + mode);
    ASSERT_EQ(spaced.code, 0) << mode << ": " << spaced.out;
    ASSERT_EQ(joined.code, 0) << mode << ": " << joined.out;
    const auto estimator = [](const std::string& out) {
      const size_t at = out.find("estimator:");
      return at == std::string::npos ? std::string() : out.substr(at, out.find('\n', at) - at);
    };
    EXPECT_FALSE(estimator(spaced.out).empty()) << spaced.out;
    EXPECT_EQ(estimator(spaced.out), estimator(joined.out)) << mode;
  }
  EXPECT_NE(run(base + "--light-paths on").out.find("light-paths=on"), std::string::npos);
  EXPECT_EQ(run(base + "--light-paths off").out.find("light-paths="), std::string::npos);
  // the flag alone is on, the scene after it still the scene
  const CmdResult alone = run("info --max-depth 3 --light-paths built-in:cornell");
  ASSERT_EQ(alone.code, 0) << alone.out;
  EXPECT_NE(alone.out.find("light-paths=on"), std::string::npos) << alone.out;
  EXPECT_NE(alone.out.find("built-in:cornell"), std::string::npos) << alone.out;
  // a word that is not a mode is not swallowed: a second positional, refused
  EXPECT_EQ(run(base + "--light-paths maybe").code, 1);

  const CmdResult twice = run("render built-in:cornell --res 8x8 --spp 2 --spp 4 --quiet -o " + tmp("cli_twice.exr"));
  EXPECT_EQ(twice.code, 1) << twice.out;
  EXPECT_NE(twice.out.find("--spp is given 2 times"), std::string::npos) << twice.out;
  EXPECT_EQ(twice.out.find("At Most"), std::string::npos) << twice.out;
  EXPECT_FALSE(fs::exists(tmp("cli_twice.exr")));
}

// --bvh chooses Embree's layout (the built-in scenes are small: auto is the fast one), and
// the image does not depend on it
TEST(Cli, BvhLayoutIsChosenAndLeavesTheImageAlone) {
  for (const char* layout : {"auto", "fast", "compact"}) {
    const CmdResult r = run(std::string("info built-in:cornell --bvh ") + layout);
    ASSERT_EQ(r.code, 0) << r.out;
    const std::string want = std::string(layout) == "compact" ? "(compact layout)" : "(fast layout)";
    EXPECT_NE(r.out.find(want), std::string::npos) << layout << ": " << r.out;
  }
  const CmdResult a = run("render built-in:cornell --quiet --spp 4 --res 32x32 --max-depth 3 --bvh fast -o " + tmp("cli_fast.exr"));
  const CmdResult b = run("render built-in:cornell --quiet --spp 4 --res 32x32 --max-depth 3 --bvh compact -o " + tmp("cli_compact.exr"));
  ASSERT_EQ(a.code, 0) << a.out;
  ASSERT_EQ(b.code, 0) << b.out;
  const CmdResult d = run("diff " + tmp("cli_fast.exr") + " " + tmp("cli_compact.exr"));
  EXPECT_EQ(d.code, 0) << d.out;
}

TEST(Cli, InfoNamesThePipeline) {
  const CmdResult r = run("info built-in:two-panels");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("pipeline: rect/mis/pick"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("lights: 101"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("bounce rays: against the whole scene"), std::string::npos) << r.out;
  const CmdResult g = run("info built-in:two-panels --pipeline general");
  EXPECT_NE(g.out.find("pipeline: general"), std::string::npos) << g.out;
  const CmdResult c = run("info built-in:cornell");
  EXPECT_NE(c.out.find("bounce rays: against the emitters"), std::string::npos) << c.out;
  const CmdResult f = run("info built-in:cornell --bounce-rays scene");
  EXPECT_NE(f.out.find("bounce rays: against the whole scene"), std::string::npos) << f.out;
}

// Many lights: info names the light picker (the BVH with its size; the alias table
// otherwise), ris takes the BVH by default, and its flags out of range are errors naming them.
TEST(Cli, LightPickerAndRisFlags) {
  CmdResult r = run("info built-in:two-panels --light-pick bvh");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("light picker: bvh (a light BVH over 101 sources"), std::string::npos) << r.out;
  r = run("info built-in:two-panels");
  EXPECT_NE(r.out.find("light picker: power (an alias table"), std::string::npos) << r.out;
  r = run("info built-in:two-panels --strategy ris");
  EXPECT_NE(r.out.find("strategy=ris light-pick=bvh"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ris-light=8 ris-bsdf=1"), std::string::npos) << r.out;
  for (const char* args : {"--ris-light -1", "--ris-bsdf 2000", "--ris-light 0 --ris-bsdf 0", "--light-pick all"}) {
    r = run(std::string("render built-in:cornell --res 8x8 --spp 1 --quiet --strategy ris -o ") + tmp("cli_ris.exr") + " " + args);
    EXPECT_NE(r.code, 0) << args << ": accepted (exit 0): " << r.out;
    EXPECT_NE(r.out.find(std::string(args).substr(0, std::string(args).find(' '))), std::string::npos) << args << ": " << r.out;
  }
  r = run(std::string("render built-in:cornell --res 8x8 --spp 1 --quiet --strategy ris -o ") + tmp("cli_ris.exr"));
  EXPECT_EQ(r.code, 0) << r.out;
}

// info prints the alias table's shares of the sources at infinity: under MIS a constant sky
// gets none (its light samples have no density there: the BSDF samples find it), with light
// sampling alone its power's share.
TEST(Cli, InfoPrintsThePicksOfTheSourcesAtInfinity) {
  const std::string path = tmp("cli_sun_sky.pbrt");
  std::ofstream(path) << "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\"\nFilm \"rgb\" \"integer xresolution\" 8 "
                         "\"integer yresolution\" 8\nWorldBegin\nLightSource \"distant\" \"rgb L\" [3 3 3]\n"
                         "LightSource \"infinite\" \"rgb L\" [0.5 0.5 0.5]\n"
                         "AttributeBegin\nAreaLightSource \"diffuse\" \"rgb L\" [4 4 4]\n"
                         "Shape \"trianglemesh\" \"point3 P\" [-1 -1 0 1 -1 0 1 1 0 -1 1 0] \"integer indices\" [0 1 2 0 2 3]\n"
                         "AttributeEnd\n";
  CmdResult r = run("info " + path);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("picks of the sources at infinity: distant "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(", sky 0; the other "), std::string::npos) << r.out;
  r = run("info " + path + " --strategy light");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("picks of the sources at infinity: distant "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find(", sky 0;"), std::string::npos) << r.out;
}

TEST(Cli, BenchJsonSchema) {
  const std::string js = tmp("cli_bench.json");
  const CmdResult r = run("bench built-in:cornell --res 16x16 --spp 2 --repeat 3 --warmup 1 --json " + js);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("samples/s: median"), std::string::npos);
  std::ifstream f(js);
  const std::string s((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  // "samples_per_second": {"median": M, "min": m, "max": x}
  auto number_after = [&](const std::string& key, size_t from) {
    const size_t k = s.find(key, from);
    EXPECT_NE(k, std::string::npos) << key << " in " << s;
    return k == std::string::npos ? -1.0 : std::strtod(s.c_str() + k + key.size(), nullptr);
  };
  const size_t at = s.find("\"samples_per_second\": {");
  ASSERT_NE(at, std::string::npos) << s;
  const double med = number_after("\"median\": ", at), mn = number_after("\"min\": ", at),
               mx = number_after("\"max\": ", at);
  EXPECT_GT(mn, 0.0);
  EXPECT_LE(mn, med);
  EXPECT_LE(med, mx);
  for (const char* key : {"\"rays_per_second\"", "\"camera\"", "\"shadow\"", "\"bounce\"", "\"time_to_first_pixel\"",
                          "\"peak_memory_bytes\"", "\"runs_samples_per_second\"", "\"pipeline\""})
    EXPECT_NE(s.find(key), std::string::npos) << key;
  // three runs recorded
  const size_t a = s.find("\"runs_samples_per_second\": ["), b = s.find(']', a);
  ASSERT_NE(a, std::string::npos);
  const std::string runs = s.substr(a, b - a);
  EXPECT_EQ(std::count(runs.begin(), runs.end(), ','), 2) << runs;
}

TEST(Cli, ProfileTraceIsChromeTraceJson) {
  const std::string tr = tmp("cli_trace.json");
  const CmdResult r = run("profile built-in:cornell --res 32x32 --spp 2 --threads 2 --roofline --trace " + tr);
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* stage : {"generate", "intersect camera", "sample lights", "sample BSDF", "intersect shadow",
                            "intersect bounce", "MIS weight", "accumulate", "scheduling", "roofline"})
    EXPECT_NE(r.out.find(stage), std::string::npos) << stage;
  std::ifstream f(tr);
  const std::string s((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  EXPECT_EQ(s.rfind("{\"traceEvents\":[", 0), 0u);
  EXPECT_NE(s.find("\"ph\":\"X\""), std::string::npos);
  EXPECT_NE(s.find("\"name\":\"intersect shadow\""), std::string::npos);
}

// Paths: --max-depth, --rr-depth and --rr-threshold out of range are errors naming the flag (0 is not
// "the default": a render of no vertex is a mistake, as --spp 0 is; resolve_options reads
// RenderFlags::max_depth 0 as "not given", so an explicit 0 needs a flag of its own, as
// spp_given); so is a file's Integrator maxdepth 0, with the file and line. info prints
// the depth a file asks for in the estimator line, and nothing about depth for a built-in
// scene (direct lighting).
TEST(Cli, PathDepthFlagsAndFileMaxDepth) {
  for (const char* args : {"--max-depth 0", "--max-depth -2", "--rr-depth -1", "--rr-threshold 0", "--rr-threshold -1",
                           "--rr-threshold nan", "--rr-threshold 1e9"}) {
    const CmdResult r = run(std::string("render built-in:cornell --res 8x8 --spp 1 --quiet -o ") + tmp("cli_depth.exr") +
                            " " + args);
    EXPECT_NE(r.code, 0) << args << ": accepted (exit 0): " << r.out;
    const std::string flag = std::string(args).substr(0, std::string(args).find(' '));
    EXPECT_NE(r.out.find(flag), std::string::npos) << args << ": " << r.out;
  }
  const std::string scene_text =
      "LookAt 0 0 5  0 0 0  0 1 0\n"
      "Camera \"perspective\" \"float fov\" 45\n"
      "Film \"rgb\" \"integer xresolution\" 8 \"integer yresolution\" 8\n"
      "Integrator \"path\" \"integer maxdepth\" [ DEPTH ]\n"
      "WorldBegin\n"
      "AttributeBegin\n"
      "AreaLightSource \"diffuse\" \"rgb L\" [ 1 1 1 ]\n"
      "Shape \"trianglemesh\" \"point3 P\" [ -1 -1 0  1 -1 0  1 1 0  -1 1 0 ] \"integer indices\" [ 0 1 2  0 2 3 ]\n"
      "AttributeEnd\n"
      "Shape \"sphere\" \"float radius\" 0.3\n";
  auto write_scene = [&](const std::string& name, const std::string& depth) {
    const std::string path = tmp(name);
    std::string text = scene_text;
    text.replace(text.find("DEPTH"), 5, depth);
    std::ofstream(path) << text;
    return path;
  };
  const std::string zero = write_scene("cli_maxdepth0.pbrt", "0");
  CmdResult r = run("render " + zero + " --quiet -o " + tmp("cli_maxdepth0.exr"));
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("cli_maxdepth0.pbrt:4"), std::string::npos) << r.out;  // file:line
  EXPECT_NE(r.out.find("maxdepth"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(tmp("cli_maxdepth0.exr")));
  r = run("info " + zero);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("cli_maxdepth0.pbrt:4"), std::string::npos) << r.out;
  const std::string seven = write_scene("cli_maxdepth7.pbrt", "7");
  r = run("info " + seven);
  ASSERT_EQ(r.code, 0) << r.out;
  const size_t est = r.out.find("estimator: ");
  ASSERT_NE(est, std::string::npos) << r.out;
  const std::string line = r.out.substr(est, r.out.find('\n', est) - est);
  EXPECT_NE(line.find("max-depth=7"), std::string::npos) << line;
  r = run("info " + seven + " --max-depth 3");  // the flag overrides the file
  EXPECT_NE(r.out.find("max-depth=3"), std::string::npos) << r.out;
  r = run("info built-in:cornell");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("estimator: "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("max-depth"), std::string::npos) << r.out;
}

// pbrt-v4's regularization: from the file's Integrator "bool regularize", overridden by
// --regularize on|off; the estimator line says it (it is biased); bad values are errors.
TEST(Cli, RegularizeFromTheFileOrTheFlag) {
  const std::string scene_text =
      "LookAt 0 0 5  0 0 0  0 1 0\n"
      "Camera \"perspective\" \"float fov\" 45\n"
      "Film \"rgb\" \"integer xresolution\" 8 \"integer yresolution\" 8\n"
      "Integrator \"path\" \"integer maxdepth\" [ 4 ] REG\n"
      "WorldBegin\n"
      "AttributeBegin\n"
      "AreaLightSource \"diffuse\" \"rgb L\" [ 1 1 1 ]\n"
      "Shape \"trianglemesh\" \"point3 P\" [ -1 -1 0  1 -1 0  1 1 0  -1 1 0 ] \"integer indices\" [ 0 1 2  0 2 3 ]\n"
      "AttributeEnd\n"
      "Material \"conductor\" \"float roughness\" 0\n"
      "Shape \"sphere\" \"float radius\" 0.3\n";
  auto write_scene = [&](const std::string& name, const std::string& reg) {
    const std::string path = tmp(name);
    std::string text = scene_text;
    text.replace(text.find("REG"), 3, reg);
    std::ofstream(path) << text;
    return path;
  };
  auto estimator = [](const std::string& out) {
    const size_t at = out.find("estimator: ");
    return at == std::string::npos ? std::string() : out.substr(at, out.find('\n', at) - at);
  };
  const std::string on = write_scene("cli_reg_on.pbrt", "\"bool regularize\" true");
  const std::string none = write_scene("cli_reg_none.pbrt", "");
  CmdResult r = run("info " + on);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(estimator(r.out).find("regularize=on"), std::string::npos) << r.out;
  r = run("info " + on + " --regularize off");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(estimator(r.out).find("regularize"), std::string::npos) << r.out;
  r = run("info " + none);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(estimator(r.out).find("regularize"), std::string::npos) << r.out;
  r = run("info " + none + " --regularize on");
  EXPECT_NE(estimator(r.out).find("regularize=on"), std::string::npos) << r.out;
  r = run("info " + none + " --regularize maybe");
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("--regularize"), std::string::npos) << r.out;
  const std::string bad = write_scene("cli_reg_bad.pbrt", "\"bool regularize\" \"yes\"");
  r = run("info " + bad);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("cli_reg_bad.pbrt:4"), std::string::npos) << r.out;
}

// --guide: the estimator line says it, with its learning and share; what it cannot
// combine with is a clear error naming the flag, not a crash.
TEST(Cli, GuideRendersAndRefusesWhatItCannotCombineWith) {
  const std::string out = tmp("cli_guide.exr");
  CmdResult r = run("render built-in:cornell --max-depth 3 --spp 4 --res 24x24 --guide --guide-learn 2 -o " + out);
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("guide=on guide-learn=2 guide-alpha=0.5"), std::string::npos) << r.out;
  r = run("render built-in:cornell --max-depth 1 --spp 4 --res 24x24 --guide -o " + out);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("--guide"), std::string::npos) << r.out;
  r = run("render built-in:cornell --max-depth 3 --spp 4 --res 24x24 --guide --guide-alpha 1.5 -o " + out);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("--guide-alpha"), std::string::npos) << r.out;
  r = run("render built-in:cornell --max-depth 3 --spp 4 --res 24x24 --guide --strategy ris -o " + out);
  EXPECT_NE(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("--guide"), std::string::npos) << r.out;
}

// `tuile diff`'s verdict: an infinity against a number or the other infinity is the largest
// relative difference (inf / inf was NaN, which compared as no larger: exit 0 at any
// tolerance), reported where it is; 0 against -0 differs in bits (exit 1 at the default
// tolerance, which asks for identical bits) by nothing in value (exit 0 at any other); a
// NaN tolerance is refused.
TEST(Cli, DiffCountsInfinitiesAndSignedZeros) {
  const std::vector<float> ones(8 * 8 * 3, 1.f), zeros(8 * 8 * 3, 0.f);
  std::vector<float> inf = ones, neg_zeros(8 * 8 * 3, -0.f), ninf = ones;
  inf[3 * (3 * 8 + 3) + 1] = INFINITY;  // pixel 3,3 channel G
  ninf[3 * (3 * 8 + 3) + 1] = -INFINITY;
  tuile::write_exr(tmp("diff_one.exr"), 8, 8, ones);
  tuile::write_exr(tmp("diff_inf.exr"), 8, 8, inf);
  tuile::write_exr(tmp("diff_ninf.exr"), 8, 8, ninf);
  tuile::write_exr(tmp("diff_zero.exr"), 8, 8, zeros);
  tuile::write_exr(tmp("diff_negzero.exr"), 8, 8, neg_zeros);
  for (const char* tol : {"", " --tolerance 1"}) {
    CmdResult r = run("diff " + tmp("diff_one.exr") + " " + tmp("diff_inf.exr") + tol);
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find("largest relative inf (pixel 3,3 channel G"), std::string::npos) << r.out;
    r = run("diff " + tmp("diff_inf.exr") + " " + tmp("diff_ninf.exr") + tol);
    EXPECT_EQ(r.code, 1) << r.out;
  }
  CmdResult r = run("diff " + tmp("diff_zero.exr") + " " + tmp("diff_negzero.exr"));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("differ: 192 of 192"), std::string::npos) << r.out;
  r = run("diff " + tmp("diff_zero.exr") + " " + tmp("diff_negzero.exr") + " --tolerance 1e-9");
  EXPECT_EQ(r.code, 0) << r.out;
  r = run("diff " + tmp("diff_one.exr") + " " + tmp("diff_one.exr"));
  EXPECT_EQ(r.code, 0) << r.out;
  r = run("diff " + tmp("diff_one.exr") + " " + tmp("diff_zero.exr") + " --tolerance nan");
  EXPECT_NE(r.out.find("--tolerance nan is not a number"), std::string::npos) << r.out;
  EXPECT_NE(r.code, 0) << r.out;
}

// An output named as a file the scene reads (its texture, its sky map, the scene file itself)
// is refused before any work: the render replaced it, and the next render read its own
// output.
TEST(Cli, AnOutputNeverReplacesWhatTheSceneReads) {
  const std::vector<float> grey(4 * 4 * 3, 0.5f);
  tuile::write_exr(tmp("cli_in_tex.exr"), 4, 4, grey);
  const std::string scene = tmp("cli_in.pbrt");
  std::ofstream(scene) << "Film \"rgb\" \"string filename\" \"cli_in_tex.exr\" \"integer xresolution\" [ 8 ] \"integer yresolution\" [ 8 ]\n"
                          "Camera \"perspective\"\nWorldBegin\nLightSource \"point\" \"rgb I\" [ 1 1 1 ]\n"
                          "Texture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"cli_in_tex.exr\"\n"
                          "Material \"diffuse\" \"texture reflectance\" \"t\"\n"
                          "Shape \"trianglemesh\" \"point3 P\" [ -1 -1 3 1 -1 3 0 1 3 ] \"point2 uv\" [ 0 0 1 0 0 1 ]\n";
  std::ifstream before_in(tmp("cli_in_tex.exr"), std::ios::binary);
  const std::string before((std::istreambuf_iterator<char>(before_in)), std::istreambuf_iterator<char>());
  for (const std::string& out : {tmp("cli_in_tex.exr"), tmp("./cli_in_tex.exr")}) {  // (the same file spelt two ways)
    const CmdResult r = run("render " + scene + " --spp 1 --quiet -o " + out);
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find("is a file the scene reads"), std::string::npos) << r.out;
  }
  std::ifstream after_in(tmp("cli_in_tex.exr"), std::ios::binary);
  const std::string after((std::istreambuf_iterator<char>(after_in)), std::istreambuf_iterator<char>());
  EXPECT_TRUE(after == before) << "the texture was replaced";
  const CmdResult ok = run("render " + scene + " --spp 1 --quiet -o " + tmp("cli_in_out.exr"));
  EXPECT_EQ(ok.code, 0) << ok.out;
}

// A command refused with exit status 1, its message saying `says`.
void expect_refused(const std::string& args, const std::string& says) {
  const CmdResult r = run(args);
  EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
  EXPECT_NE(r.out.find(says), std::string::npos) << args << "\n" << r.out;
}

// What is written beside an output is checked before any work too: a directory in the PNG
// preview's or the checkpoint's place (the EXR was written, then the preview failed), a
// checkpoint that is a directory (an I/O library's message naming nothing), and envmap's
// output (checked after the conversion) and its input's negative texels (the converted map
// was written, then refused by the scene that named it).
TEST(Cli, WhatIsWrittenBesideAnOutputIsCheckedFirst) {
  const std::string dir = tmp("cli_beside");
  fs::remove_all(dir);
  fs::create_directories(dir + "/p.png");
  fs::create_directories(dir + "/c.exr.checkpoint");
  expect_refused("render --res 16x16 --spp 1 -o " + dir + "/p.exr", "p.png: is a directory");
  EXPECT_FALSE(fs::exists(dir + "/p.exr"));
  expect_refused("render --res 16x16 --spp 1 -o " + dir + "/c.exr", "c.exr.checkpoint: is a directory");
  expect_refused("render --res 16x16 --spp 1 --resume -o " + dir + "/c.exr", "c.exr.checkpoint");
  std::vector<float> map(16 * 8 * 3, 1.f);
  tuile::write_exr(dir + "/in.exr", 16, 8, map);
  fs::create_directories(dir + "/out.exr");
  expect_refused("envmap " + dir + "/in.exr " + dir + "/out.exr", "out.exr: is a directory");
  map[7] = -1.f;
  tuile::write_exr(dir + "/in.exr", 16, 8, map);
  expect_refused("envmap " + dir + "/in.exr " + dir + "/neg.exr", "negative");
  EXPECT_FALSE(fs::exists(dir + "/neg.exr"));
}

// The measuring commands' outputs are checked before their work: converge's --csv in a
// missing folder (the folder, at any depth, was created), bench's --json, profile's --trace
// and --json naming one file (one replaced the other), figures' --out naming a file.
TEST(Cli, MeasuringCommandsCheckTheirOutputsFirst) {
  const std::string dir = tmp("cli_measure");
  fs::remove_all(dir);
  fs::create_directories(dir);
  expect_refused("converge built-in:two-panels --res 16x16 --csv " + dir + "/missing/deeper/c.csv", "--csv");
  EXPECT_FALSE(fs::exists(dir + "/missing"));
  expect_refused("bench built-in:cornell --res 16x16 --spp 1 --repeat 1 --json " + dir + "/missing/b.json", "does not exist");
  expect_refused("profile built-in:cornell --res 16x16 --spp 1 --json " + dir + "/t.json --trace " + dir + "/./t.json", "one file");
  std::ofstream(dir + "/a-file") << "x";
  expect_refused("figures --quick --out " + dir + "/a-file", "not a folder");
}
