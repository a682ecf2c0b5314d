// The pbrt-v4 reader's file loading at the end of parsing: the PLY meshes and the image
// textures a material reaches are read in parallel (oneTBB, one task per file, largest
// first); errors in PLY files become load errors at the Shape that named them, unreadable
// images of spectrum textures a warning and grey 0.5 (of float textures: an error at the
// Texture, when textures are resolved).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "image.h"
#include "loader_state.h"
#include "ply.h"
#include "util.h"

namespace tuile::pbrt {

void Loader::load_files() {
  // Images only when a material reaches them.
  std::vector<char> seen(texdefs_.size(), 0);
  std::vector<int> todo;
  for (const SpectrumFix& f : spectrum_fixes_) todo.push_back(f.def);
  while (!todo.empty()) {
    const int td = todo.back();
    todo.pop_back();
    if (seen[size_t(td)]) continue;
    seen[size_t(td)] = 1;
    const TexDef& d = texdefs_[size_t(td)];
    if (d.job >= 0) images_[size_t(d.job)].needed = true;
    if (d.a >= 0) todo.push_back(d.a);
    if (d.b >= 0) todo.push_back(d.b);
  }
  std::vector<char> seen_float(float_defs_.size(), 0);
  for (const FloatFix& f : float_fixes_) todo.push_back(f.def);
  while (!todo.empty()) {
    const int fd = todo.back();
    todo.pop_back();
    if (fd < 0 || seen_float[size_t(fd)]) continue;
    seen_float[size_t(fd)] = 1;
    const FloatTexDef& d = float_defs_[size_t(fd)];
    if (d.job >= 0) images_[size_t(d.job)].needed = true;
    for (int o : {d.a, d.b, d.amount}) todo.push_back(o);
  }
  // One task per file, largest first.
  std::vector<int> order;
  for (size_t i = 0; i < plys_.size(); ++i) {
    std::error_code ec;
    plys_[i].size = std::filesystem::file_size(plys_[i].path, ec);
    order.push_back(int(i));
  }
  for (size_t i = 0; i < images_.size(); ++i)
    if (images_[i].needed) order.push_back(-1 - int(i));
  auto size_of = [&](int o) -> uintmax_t {
    if (o >= 0) return plys_[size_t(o)].size;
    std::error_code ec;
    const uintmax_t s = std::filesystem::file_size(images_[size_t(-1 - o)].path, ec);
    return ec ? 0 : 4 * s;  // decoding costs more per byte than PLY parsing
  };
  std::vector<std::pair<uintmax_t, int>> sized;
  for (int o : order) sized.push_back({size_of(o), o});
  std::stable_sort(sized.begin(), sized.end(), [](auto& a, auto& b) { return a.first > b.first; });
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, sized.size(), 1),
      [&](const tbb::blocked_range<size_t>& r) {
        for (size_t k = r.begin(); k < r.end(); ++k) {
          const int o = sized[k].second;
          if (o < 0) {
            ImageJob& j = images_[size_t(-1 - o)];
            try {
              j.ok = load_image(j.path, j.encoding, j.tex, j.reason);
            } catch (const std::exception& e) {
              j.ok = false;
              j.reason = e.what();
              j.tex = Texture();
            }
            continue;
          }
          PlyJob& j = plys_[size_t(o)];
          Mesh& m = meshes_[j.mesh].mesh;
          try {
            std::string data, reason;
            if (!read_file(j.path, data, reason)) {
              j.error = "cannot read mesh file '" + j.path + "': " + reason;
              j.expected = "an existing, readable PLY file";
              continue;
            }
            PlyMesh ply = parse_ply(data, true);
            std::string().swap(data);
            m.positions = std::move(ply.positions);
            m.indices = std::move(ply.indices);
            m.uvs = std::move(ply.uvs);
            j.degenerate = ply.degenerate;
            j.polygons = ply.polygons;
            transform_positions(j.ctm, m.positions.data(), m.positions.size() / 3);
            orient_by_normals(m, ply.normals, j.ctm, j.ro);
            set_shading_normals(m, ply.normals, j.ctm, j.ro);
          } catch (const PlyError& e) {
            j.error = "in mesh file '" + j.path + "': " + e.what();
            j.expected = e.expected;
          } catch (const std::exception& e) {
            j.error = "cannot load mesh file '" + j.path + "': " + e.what();
            j.expected = "a PLY file that fits in memory";
          }
        }
      },
      tbb::simple_partitioner());
  size_t degenerate = 0, polygons = 0;
  std::string first_degenerate, first_polygon;
  for (const PlyJob& j : plys_) {
    if (!j.error.empty()) fail(j.where_file, j.line, j.col, j.error, j.expected);
    if (j.degenerate && first_degenerate.empty()) first_degenerate = j.path;
    if (j.polygons && first_polygon.empty()) first_polygon = j.path;
    degenerate += j.degenerate;
    polygons += j.polygons;
  }
  if (degenerate)
    note("plydegenerate", std::to_string(degenerate) + " degenerate PLY faces (zero area, or a repeated vertex) skipped (first in " +
                              first_degenerate + ")");
  if (polygons)
    warn("plypolygon", std::to_string(polygons) + " PLY faces with more than 4 vertices were fan-triangulated (first in " +
                           first_polygon + ")");
  // one policy for missing images (float textures: loader_textures.cpp): a constant with a
  // warning, or with --strict pbrt-v4's error
  for (const ImageJob& j : images_) {
    if (!j.needed || j.ok) continue;
    if (strict)
      throw SceneError(j.where + ": error: cannot read image '" + j.path + "': " + j.reason +
                       " (expected an existing, readable image file: --strict)");
    warn("image:" + j.path, j.where + ": cannot read image '" + j.path + "' (" + j.reason +
                                "): constant grey 0.5 used (--strict: an error)");
  }
}

}  // namespace tuile::pbrt
