// Files that are never left half-written: a file is written under a temporary name in
// its own directory, flushed to disk, then renamed over the destination, so a crash, a
// kill or a full disk leaves either the previous file or the new one, never a truncated
// one. And the check that an output can be written at all, made before any work.
#pragma once
#include <functional>
#include <string>
#include <vector>

namespace tuile {

// Calls write(tmp) to write the whole file at a temporary path beside `path`, then syncs
// it and renames it to `path` (and syncs the directory). On any failure the temporary
// file is removed, the previous `path` is left as it was, and the error (naming `path`)
// propagates as std::runtime_error.
void write_atomically(const std::string& path, const std::function<void(const std::string& tmp)>& write);

// Throws std::invalid_argument naming `path` when its extension (case-insensitive) is not
// one of `extensions` (".exr", ...), its directory does not exist or is not a directory, or
// a file cannot be created there (probed with a temporary file, removed at once).
void check_output_path(const std::string& path, const std::vector<std::string>& extensions);

}  // namespace tuile
