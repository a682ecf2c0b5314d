// `tuile diff A.exr B.exr`: whether two renders are bit-identical, and if not by how much
// they differ (largest absolute and relative difference, how many values differ, where the
// worst one is; channel means, relMSE and region ratios). Exit status 0 when identical (in every bit, with the default tolerance 0) or within --tolerance, 1 when not, 2 when an
// image cannot be read or the sizes differ.
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>

#include "app/commands.h"
#include "measure/metrics.h"
#include "scene/image_io.h"

namespace tuile {

void add_diff_flags(CLI::App& app, DiffFlags& f) {
  app.add_option("a", f.a, "first image (.exr)")->required();
  app.add_option("b", f.b, "second image (.exr)")->required();
  app.add_option("--tolerance", f.tolerance,
                 "accept a largest relative difference |a - b| / max(|a|, |b|) up to this (default 0: identical bits)")
      ->check(CLI::Validator(
          [](std::string& s) {  // (CLI::Range lets a NaN through: every comparison with it is false)
            const double v = std::strtod(s.c_str(), nullptr);
            return v >= 0 && v <= 1 ? std::string() : "--tolerance " + s + " is not a number in [0, 1]";
          },
          "", ""));
}

int run_diff(const DiffFlags& f) {
  int wa = 0, ha = 0, wb = 0, hb = 0;
  std::vector<float> a, b;
  try {
    a = read_exr(f.a, wa, ha);
    b = read_exr(f.b, wb, hb);
  } catch (const std::exception& e) {
    std::cerr << "tuile diff: " << e.what() << "\n";
    return 2;
  }
  if (wa != wb || ha != hb) {
    std::cerr << "tuile diff: " << f.a << " is " << wa << "x" << ha << " but " << f.b << " is " << wb << "x" << hb << "\n";
    return 2;
  }
  size_t differing = 0, worst = 0;
  double max_abs = 0, max_rel = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::memcmp(&a[i], &b[i], sizeof(float)) == 0) continue;
    if (differing++ == 0) worst = i;  // (0 against -0 differs in bits alone: its relative difference is 0)
    const double x = a[i], y = b[i];
    const double d = std::fabs(x - y);
    // NaN or an infinity against anything else (a number, the other infinity) counts as the
    // largest possible difference (inf / inf and 0 / 0 would be NaN, which compares as no larger)
    const double rel = !std::isfinite(d) ? INFINITY : d == 0 ? 0 : d / std::max(std::fabs(x), std::fabs(y));
    if (!std::isfinite(d) || d > max_abs) max_abs = std::isfinite(d) ? d : INFINITY;
    if (rel > max_rel) {
      max_rel = rel;
      worst = i;
    }
  }
  if (differing == 0) {
    std::printf("identical: %s and %s (%dx%d, every bit)\n", f.a.c_str(), f.b.c_str(), wa, ha);
    return 0;
  }
  const size_t px = worst / 3;
  std::printf("differ: %zu of %zu values; largest |a - b| %.3g, largest relative %.3g (pixel %zu,%zu channel %c: %.9g vs %.9g)\n",
              differing, a.size(), max_abs, max_rel, px % size_t(wa), px / size_t(wa), "RGB"[worst % 3],
              double(a[worst]), double(b[worst]));
  // How the images differ as a whole: the channel means (and a / b), relMSE of a against b
  // as the reference, and a / b of the mean luminance over a 4 x 4 grid of regions.
  double ma[3] = {}, mb[3] = {};
  constexpr int grid = 4;
  double ra[grid][grid] = {}, rb[grid][grid] = {};
  for (size_t p = 0; p < a.size() / 3; ++p) {
    const size_t x = p % size_t(wa), y = p / size_t(wa);
    const int gx = static_cast<int>(x * grid / size_t(wa)), gy = static_cast<int>(y * grid / size_t(ha));
    for (int c = 0; c < 3; ++c) {
      ma[c] += a[3 * p + c];
      mb[c] += b[3 * p + c];
    }
    ra[gy][gx] += 0.2126 * a[3 * p] + 0.7152 * a[3 * p + 1] + 0.0722 * a[3 * p + 2];
    rb[gy][gx] += 0.2126 * b[3 * p] + 0.7152 * b[3 * p + 1] + 0.0722 * b[3 * p + 2];
  }
  const double n = static_cast<double>(a.size() / 3);
  std::printf("means R G B: a %.5g %.5g %.5g, b %.5g %.5g %.5g, a / b %.4f %.4f %.4f\n", ma[0] / n, ma[1] / n, ma[2] / n,
              mb[0] / n, mb[1] / n, mb[2] / n, ma[0] / mb[0], ma[1] / mb[1], ma[2] / mb[2]);
  std::printf("relMSE of a against b: %.4g\n", relmse(a, b));
  std::printf("a / b of the mean luminance, %dx%d regions (top row first):\n", grid, grid);
  for (int gy = 0; gy < grid; ++gy) {
    std::printf(" ");
    for (int gx = 0; gx < grid; ++gx) std::printf(" %7.4f", rb[gy][gx] > 0 ? ra[gy][gx] / rb[gy][gx] : NAN);
    std::printf("\n");
  }
  // the default tolerance, 0, asks for identical bits; above it, values within the tolerance
  return (f.tolerance > 0 && max_rel <= f.tolerance) ? 0 : 1;
}

}  // namespace tuile
