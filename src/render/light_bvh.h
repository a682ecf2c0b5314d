// Building the light BVH (kernels/light/bvh.h) over a scene's sources: each source's
// bounds (box, cone of normals, power) as pbrt-v4 gives them, then a binary tree split by
// pbrt-v4's cost (power times the cone's solid-angle measure times the box's area, over 12
// buckets per axis), in parallel over subtrees and, at the top, over the sources of a
// node. The layout is fixed by the split choices alone (a subtree over k sources takes
// 2k - 1 nodes, depth-first), and every sum runs over fixed ranges in a fixed order, so
// the tree and every pick are the same bits for any thread count.
// Memory: 28 bytes per node (the quantized bounds, kernels/light/bvh.h) and 8 per light
// (its bit trail), 64 per source less 28 for the whole tree, plus 4 per distant source.
#pragma once
#include <cstdint>
#include <vector>

#include "light/bvh.h"
#include "scene/scene.h"

namespace tuile {

struct LightBvh {
  float grid_lo[3] = {0, 0, 0}, grid_step[3] = {0, 0, 0};  // the nodes' box grid
  std::vector<uint32_t> box_x, box_y, box_z, axis, cone;   // per node, quantized
  std::vector<float> phi;
  std::vector<int32_t> child;
  std::vector<uint32_t> trail_lo, trail_hi;  // per light (with the outside / distant marks)
  std::vector<int32_t> distant_light;        // the distant sources' indices
  int depth = 0;                             // the deepest leaf's depth (at most 62)

  LightBvhView view() const;
  size_t bytes() const;  // memory of the arrays above
};

// The tree over lights (the scene's light table, in its order). Sources of zero power are
// never picked (pmf 0), as in pbrt-v4.
LightBvh build_light_bvh(const std::vector<Light>& lights);

}  // namespace tuile
