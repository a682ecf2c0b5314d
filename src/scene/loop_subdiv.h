// Loop subdivision of a triangle mesh, as pbrt-v4's `Shape "loopsubdiv"` renders it
// (Loop 1987; pbrt-v4's util/loopsubdiv.cpp): `levels` rounds of splitting every triangle
// into four (even vertices by the one-ring rule, beta = 3/16 at valence 3 and 3/(8n)
// otherwise; odd vertices 3/8, 3/8, 1/8, 1/8; boundaries as cubic B-spline curves:
// 3/4, 1/8, 1/8 and 1/2, 1/2), then every vertex pushed to its limit position (gamma =
// 1 / (n + 3/(8 beta)) on the one ring, 3/5, 1/5, 1/5 on a boundary) and given the
// normal of the limit surface from its tangents. The normals follow pbrt-v4's convention
// (the cross product of its two tangents over the ring in its order), so a file's
// surfaces face the way they face in pbrt-v4. Texture coordinates are not carried (pbrt-v4
// drops them too).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace tuile {

struct LoopMesh {
  std::vector<float> positions;   // x y z per vertex (the input's original vertices first, in their order)
  std::vector<uint32_t> indices;  // 3 per triangle, the input's winding
  std::vector<float> normals;     // x y z per vertex, unit (a zero vector where the tangents are degenerate)
};

// The mesh subdivided `levels` times (0: only the limit positions and normals of the
// control mesh). Returns false with `why` when the control mesh is not a manifold Loop's
// rules apply to: an edge shared by more than two triangles, two triangles that share an
// edge in the same direction (inconsistent winding), a vertex whose triangles form more
// than one fan, a degenerate triangle (a repeated vertex), an unused vertex, or a result
// above `max_triangles`.
bool loop_subdivide(const std::vector<float>& positions, const std::vector<uint32_t>& indices, int levels, LoopMesh& out,
                    std::string& why, size_t max_triangles = size_t(1) << 28);

}  // namespace tuile
