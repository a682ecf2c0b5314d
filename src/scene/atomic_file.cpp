// write_atomically and check_output_path: POSIX temporary files, fsync and rename.
#include "scene/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace tuile {

namespace {

std::string directory_of(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

void sync_path(const std::string& path, bool directory) {
  const int fd = ::open(path.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0) return;  // nothing to sync (a directory that cannot be opened read-only)
  ::fsync(fd);
  ::close(fd);
}

// A unique name beside path: "path.tmp-PID-N" (removed on failure, renamed on success); a
// long file name is shortened first, so that the temporary name stays within the 255 bytes
// a name may have (a name of 240 bytes made every write of it fail).
std::string temporary_beside(const std::string& path) {
  static int counter = 0;
  const std::filesystem::path p(path);
  std::string name = p.filename().string();
  if (name.size() > 200) name.resize(200);
  return (p.parent_path() / (name + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++))).string();
}

}  // namespace

void write_atomically(const std::string& path, const std::function<void(const std::string& tmp)>& write) {
  const std::string tmp = temporary_beside(path);
  try {
    write(tmp);
    struct stat st {};
    if (::stat(tmp.c_str(), &st) != 0) throw std::runtime_error("the temporary file vanished");
    const int fd = ::open(tmp.c_str(), O_RDONLY);
    if (fd < 0 || ::fsync(fd) != 0) {
      const std::string why = std::strerror(errno);
      if (fd >= 0) ::close(fd);
      throw std::runtime_error("cannot flush " + tmp + ": " + why);
    }
    ::close(fd);
    if (std::rename(tmp.c_str(), path.c_str()) != 0)
      throw std::runtime_error("cannot rename " + tmp + ": " + std::strerror(errno));
    sync_path(directory_of(path), true);
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    const std::string what = e.what();
    // errors from write() already name the path; others get it here
    throw std::runtime_error(what.find(path) != std::string::npos ? what : path + ": " + what);
  }
}

void check_output_path(const std::string& path, const std::vector<std::string>& extensions) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) {
    std::string list;
    for (const std::string& e : extensions) list += (list.empty() ? "" : ", ") + e;
    throw std::invalid_argument(path + ": unknown output extension '" + ext + "' (expected " + list + ")");
  }
  const std::string dir = directory_of(path);
  std::error_code ec;
  if (!std::filesystem::exists(dir, ec))
    throw std::invalid_argument(path + ": the output directory " + dir + " does not exist");
  if (!std::filesystem::is_directory(dir, ec))
    throw std::invalid_argument(path + ": " + dir + " is not a directory");
  if (std::filesystem::is_directory(path, ec)) throw std::invalid_argument(path + ": is a directory");
  // the longest name written beside it: its checkpoint (".checkpoint") or preview (".png")
  const size_t name = std::filesystem::path(path).filename().string().size();
  if (name + std::strlen(".checkpoint") > 255)
    throw std::invalid_argument(path + ": the file name is " + std::to_string(name) +
                                " bytes long; its checkpoint's name (+ \".checkpoint\") would pass the 255 a name may have");
  const std::string probe = temporary_beside(path);
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0644);
  if (fd < 0)
    throw std::invalid_argument(path + ": cannot write in " + dir + ": " + std::strerror(errno));
  ::close(fd);
  ::unlink(probe.c_str());
}

}  // namespace tuile
