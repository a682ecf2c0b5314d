// Building the light BVH (kernels/light/bvh.h) over a scene's sources: each source's
// bounds (box, cone of normals, power) as pbrt-v4 gives them, then a binary tree split by
// pbrt-v4's cost (power times the cone's solid-angle measure times the box's area, over 12
// buckets per axis), in parallel over subtrees. The layout is fixed by the split choices
// alone (a subtree over k sources takes 2k - 1 nodes, depth-first), so the tree and every
// pick are the same bits for any thread count.
#pragma once
#include <cstdint>
#include <vector>

#include "light/bvh.h"
#include "scene/scene.h"

namespace tuile {

struct LightBvh {
  std::vector<float> cx, cy, cz, radius, wx, wy, wz, phi, cos_o, cos_e, two_sided;
  std::vector<int32_t> child;
  std::vector<uint32_t> trail_lo, trail_hi;
  std::vector<int32_t> where;          // per light: 1 in the tree, 2 distant, 0 never picked
  std::vector<int32_t> distant_light;  // the distant sources' indices
  int depth = 0;                       // the deepest leaf's depth

  LightBvhView view() const;
  size_t bytes() const;  // memory of the arrays above
};

// The tree over lights (the scene's light table, in its order). Sources of zero power are
// never picked (pmf 0), as in pbrt-v4.
LightBvh build_light_bvh(const std::vector<Light>& lights);

}  // namespace tuile
