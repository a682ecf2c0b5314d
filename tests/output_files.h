// Helpers of the tests that run tuile as a child process and read what it wrote: running a
// command with its output captured, a temporary directory removed at the end, and a
// bit-for-bit comparison of two EXRs.
#pragma once
#include <stdlib.h>
#include <sys/wait.h>

#include <cstdio>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "scene/image_io.h"

namespace tuile::testing {

struct CmdResult {
  int code;         // the exit status (-1: not run, or killed by a signal)
  std::string out;  // stdout and stderr
};
// Runs `binary args` through the shell, stderr into stdout.
inline CmdResult run_command(const std::string& binary, const std::string& args) {
  const std::string cmd = binary + " " + args + " 2>&1";
  FILE* f = popen(cmd.c_str(), "r");
  CmdResult r{-1, ""};
  if (!f) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, f)) > 0) r.out.append(buf, n);
  const int st = pclose(f);
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

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
