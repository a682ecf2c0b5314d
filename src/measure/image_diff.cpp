// `tuile diff A.exr B.exr`: whether two renders are bit-identical, and if not by how much
// they differ (largest absolute and relative difference, how many values differ, where the
// worst one is). Exit status 0 when identical or within --tolerance, 1 when not, 2 when an
// image cannot be read or the sizes differ.
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>

#include "app/commands.h"
#include "scene/image_io.h"

namespace tuile {

void add_diff_flags(CLI::App& app, DiffFlags& f) {
  app.add_option("a", f.a, "first image (.exr)")->required();
  app.add_option("b", f.b, "second image (.exr)")->required();
  app.add_option("--tolerance", f.tolerance,
                 "accept a largest relative difference |a - b| / max(|a|, |b|) up to this (default 0: identical bits)")
      ->check(CLI::Range(0.0, 1.0));
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
    ++differing;
    const double x = a[i], y = b[i];
    const double d = std::fabs(x - y);
    // NaN against a number (or the other way) counts as the largest possible difference.
    const double rel = std::isnan(d) ? INFINITY : d / std::max(std::fabs(x), std::fabs(y));
    if (std::isnan(d) || d > max_abs) max_abs = std::isnan(d) ? INFINITY : d;
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
  return max_rel <= f.tolerance ? 0 : 1;
}

}  // namespace tuile
