// The bridge to matplotlib: the figures' data as JSON and .npy files in a temporary
// folder, drawn by one run of python/tuile/plot.py.
#include "measure/plot.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

extern char** environ;

#ifndef TUILE_SOURCE_DIR
#define TUILE_SOURCE_DIR "."
#endif
#ifndef TUILE_PYTHON_EXECUTABLE
#define TUILE_PYTHON_EXECUTABLE "python3"
#endif

namespace tuile {

namespace {

std::string json_string(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (ch == '"' || ch == '\\') o += '\\', o += ch;
    else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      o += buf;
    } else o += ch;
  }
  return o + "\"";
}

// A finite number as JSON (17 digits: the plot gets the measured values); NaN and
// infinities, which JSON lacks, as null (matplotlib leaves a gap).
std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string json_numbers(const std::vector<double>& v) {
  std::string o = "[";
  for (size_t i = 0; i < v.size(); ++i) o += (i ? ", " : "") + json_number(v[i]);
  return o + "]";
}

// A private folder for the run's files, removed when the run ends.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    const char* base = std::getenv("TMPDIR");
    std::string tmpl = std::string(base && *base ? base : "/tmp") + "/tuile-plot-XXXXXX";
    if (!mkdtemp(tmpl.data())) throw std::runtime_error("cannot make a temporary folder for the plots: " + tmpl + ": " + std::strerror(errno));
    path = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

}  // namespace

std::string plot_python() {
  const char* env = std::getenv("TUILE_PYTHON");
  return env && *env ? env : TUILE_PYTHON_EXECUTABLE;
}

std::string plot_script() { return std::string(TUILE_SOURCE_DIR) + "/python/tuile/plot.py"; }

void write_npy(const std::string& path, const std::vector<size_t>& shape, const float* data) {
  std::string dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (";
  size_t n = 1;
  for (size_t i = 0; i < shape.size(); ++i) {
    dict += std::to_string(shape[i]) + (shape.size() == 1 || i + 1 < shape.size() ? ", " : "");
    n *= shape[i];
  }
  dict += "), }";
  // magic (6) + version (2) + header length (2) + header, padded with spaces and ended
  // by a newline to a multiple of 64 bytes
  size_t total = 10 + dict.size() + 1;
  dict.append((64 - total % 64) % 64, ' ');
  dict += '\n';
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  const unsigned char head[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<unsigned char>(dict.size() & 0xff),
                                  static_cast<unsigned char>(dict.size() >> 8)};
  out.write(reinterpret_cast<const char*>(head), 10);
  out.write(dict.data(), static_cast<std::streamsize>(dict.size()));
  static_assert(sizeof(float) == 4);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(n * sizeof(float)));  // x86-64: little-endian
  if (!out) throw std::runtime_error(path + ": error writing");
}

void draw_with_matplotlib(const std::vector<Plot>& plots, const std::vector<Sheet>& sheets) {
  TempDir dir;
  std::ostringstream spec;
  spec << "{\"plots\": [";
  for (size_t i = 0; i < plots.size(); ++i) {
    const Plot& p = plots[i];
    spec << (i ? ",\n" : "\n") << "{\"output\": " << json_string(std::filesystem::absolute(p.output).string())
         << ", \"title\": " << json_string(p.title) << ", \"xlabel\": " << json_string(p.xlabel)
         << ", \"ylabel\": " << json_string(p.ylabel) << ", \"guide_slope\": " << json_number(p.guide_slope)
         << ", \"guide_label\": " << json_string(p.guide_label) << ", \"series\": [";
    for (size_t k = 0; k < p.series.size(); ++k)
      spec << (k ? ", " : "") << "{\"name\": " << json_string(p.series[k].name) << ", \"x\": " << json_numbers(p.series[k].x)
           << ", \"y\": " << json_numbers(p.series[k].y) << "}";
    spec << "]}";
  }
  spec << "],\n\"sheets\": [";
  int file = 0;
  for (size_t i = 0; i < sheets.size(); ++i) {
    const Sheet& s = sheets[i];
    spec << (i ? ",\n" : "\n") << "{\"output\": " << json_string(std::filesystem::absolute(s.output).string())
         << ", \"title\": " << json_string(s.title) << ", \"columns\": " << s.columns << ", \"panels\": [";
    for (size_t k = 0; k < s.panels.size(); ++k) {
      const SheetPanel& p = s.panels[k];
      if (p.data.size() != static_cast<size_t>(p.width) * static_cast<size_t>(p.height) * static_cast<size_t>(p.channels))
        throw std::logic_error("sheet panel '" + p.label + "': its data does not match its size");
      const std::string npy = (dir.path / ("panel-" + std::to_string(file++) + ".npy")).string();
      write_npy(npy, {static_cast<size_t>(p.height), static_cast<size_t>(p.width), static_cast<size_t>(p.channels)},
                p.data.data());
      spec << (k ? ", " : "") << "{\"label\": " << json_string(p.label) << ", \"display\": " << json_string(p.display)
           << ", \"file\": " << json_string(npy) << "}";
    }
    spec << "]}";
  }
  spec << "]}\n";
  const std::string spec_path = (dir.path / "figures.json").string();
  {
    std::ofstream out(spec_path);
    out << spec.str();
    if (!out) throw std::runtime_error(spec_path + ": error writing");
  }
  // python3 plot.py SPEC, its output (the files it wrote, or its error) kept for the message
  const std::string python = plot_python(), script = plot_script(), log = (dir.path / "log.txt").string();
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  std::vector<std::string> args = {python, script, spec_path};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  const int err = posix_spawnp(&pid, python.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (err != 0)
    throw std::runtime_error("cannot run " + python + " to draw the figures with matplotlib: " + std::strerror(err) +
                             " (set TUILE_PYTHON to a python3 with numpy and matplotlib: Debian's python3-numpy, "
                             "python3-matplotlib; make deps installs them)");
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  std::ifstream in(log);
  std::stringstream what;
  what << in.rdbuf();
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw std::runtime_error(python + " " + script + " failed to draw the figures (matplotlib: Debian's python3-matplotlib, "
                             "make deps installs it):\n" + what.str());
}

}  // namespace tuile
