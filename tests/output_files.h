// Helpers of the tests that run tuile as a child process and read what it wrote: a
// temporary directory removed at the end, and a bit-for-bit comparison of two EXRs.
#pragma once
#include <stdlib.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "scene/image_io.h"

namespace tuile::testing {

struct TempDir {
  std::filesystem::path path;
  TempDir() {
    char tmpl[] = "/tmp/tuile-test-XXXXXX";
    path = mkdtemp(tmpl);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// The R G B of two EXRs, bit for bit (and the same size).
inline bool same_pixels(const std::string& a, const std::string& b) {
  int wa = 0, ha = 0, wb = 0, hb = 0;
  const std::vector<float> x = read_exr(a, wa, ha), y = read_exr(b, wb, hb);
  return wa == wb && ha == hb && x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(float)) == 0;
}

}  // namespace tuile::testing
