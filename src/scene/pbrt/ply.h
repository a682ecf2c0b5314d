// PLY meshes (ASCII, binary little and big endian) parsed from one in-memory buffer.
#pragma once
#include <cstdint>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tuile::pbrt {

struct PlyMesh {
  std::vector<float> positions;  // xyz per vertex, object space
  std::vector<float> uvs;        // uv per vertex when the file has u/v (or s/t)
  std::vector<float> normals;    // nx ny nz per vertex when asked for and present
  std::vector<uint32_t> indices; // 3 per triangle; quads split into (0,1,2),(0,2,3)
  size_t degenerate = 0;         // faces skipped: fewer than 3 vertices, repeated index, zero area
  size_t polygons = 0;           // faces of more than 4 vertices (fan-triangulated)
};

// A problem in a PLY file: what() says what is wrong, expected what was wanted instead.
struct PlyError : std::runtime_error {
  PlyError(const std::string& what, const std::string& exp) : std::runtime_error(what), expected(exp) {}
  std::string expected;
};

// Throws PlyError. Binary elements of at least `chunk` records (vertices; faces that are
// all triangles) are decoded in parallel blocks of that many (oneTBB): the same mesh, the
// same errors as the sequential reader.
PlyMesh parse_ply(std::string_view data, bool want_normals, uint64_t chunk = uint64_t(1) << 18);

}  // namespace tuile::pbrt
