// The path guide's learning (--guide; the kernels' side is kernels/wave/guide.h): a binary
// tree over the scene's box whose leaves gather, per cell of the directional grid, the
// light the paths of earlier samples brought to their vertices there. Learning runs in
// iterations that end at samples 1, 2, 4, 8, ... up to Estimator::guide_learn (Müller et
// al. 2017's doubling): the samples of one iteration are guided by what the iteration
// before learned, record into the tree, and at its end the tree is refined where many
// records fell and each leaf's cells become its distribution. After the last iteration the
// guide stays as it is.
// Deterministic: a record is an integer (fixed point) added atomically, so the sums, and
// the guide made of them, do not depend on threads or tile order; and the guide that samples
// [b_k, b_k+1) use is a function of the samples before b_k only, so an interrupted render
// resumed at any pass gets the same guide (the renderer learns it again from those samples).
#pragma once
#include <array>
#include <cstdint>
#include <vector>

#include "wave/guide.h"

namespace tuile {

// The four cells of the directional grid nearest the unit direction d and their bilinear
// weights (summing to 1): the cells whose centres surround d's point of the square, those
// past an edge of the square taken where the octahedral map puts them (the edge folds onto
// itself, mirrored), so the four are d's neighbours on the sphere.
void guide_bilinear_cells(const Vec3<float>& d, int cell[4], float w[4]) noexcept;

class Guide {
 public:
  // The scene's box (lo, hi), the samples learning runs for, the guide's share alpha.
  Guide(const float* lo, const float* hi, uint32_t learn, float alpha);

  // Back to nothing learned: one leaf, no distribution.
  void reset();
  // The samples [0, learned()) made the distributions (0: none yet).
  uint32_t learned() const noexcept { return learned_; }
  uint32_t learn() const noexcept { return learn_; }
  // The end of the learning iteration that sample s belongs to (s < learn()).
  uint32_t iteration_end(uint32_t s) const noexcept;
  // Adds one record: at point (x, y, z) of class cls (guide_class of its normal facing the
  // viewer, or guide_medium_class) light of luminance `value` per unit density came along
  // the unit direction d (the path's L_in cos / p; L_in / p in a medium).
  // Filtered in direction (after Müller 2019, "Practical Path Guiding in Production"): the
  // value is shared among the four cells nearest d by bilinear weights
  // (guide_bilinear_cells), so that a direction's light does not depend on which side of a
  // cell's edge it fell. Thread-safe.
  void record(float x, float y, float z, int cls, float dx, float dy, float dz, float value) noexcept;
  // Ends the iteration that ends at sample `until`: refines the tree, turns the records into
  // the distributions, clears them.
  void rebuild(uint32_t until);
  // Drops the records of an iteration that did not finish.
  void drop_records();
  // The records since the last rebuild: every slot's cell sums, then every slot's count
  // (a slot is a node and class). set_records puts back such an array, e.g. the sums of
  // every process's records (a distributed render: the sums are integers, so they do not
  // depend on which process recorded what). Its size must be records().size().
  std::vector<uint64_t> records() const;
  void set_records(const std::vector<uint64_t>& r);

  const GuideView& view() const noexcept { return view_; }
  int leaves() const noexcept;
  int distributions() const noexcept { return static_cast<int>(marg_.size() / (guide_res + 1)); }
  using Dists = std::array<int32_t, guide_classes>;
  int node_of(float x, float y, float z) const noexcept;  // the leaf holding the point

  // a leaf splits while it holds more than split_records * sqrt(iteration's samples) records
  static constexpr double split_records = 4000;
  static constexpr int max_depth = 24;
  static constexpr uint64_t min_records = 64;  // a leaf with fewer learns no distribution
  // A record's value in fixed point: 2^20, and records clamp to 2^23 (the guide only, never
  // the image), so that a cell's 64-bit sum holds 2^21 records at the clamp. The clamp is
  // high: the rare records that carry most of a caustic's light (a lamp of radiance 5e5
  // seen through a glass sphere, over a density of 1 / (4 pi)) are what the guide must learn.
  static constexpr double fixed_scale = 1048576.0;
  static constexpr float max_value = 8388608.f;

 private:
  struct Box {
    float lo[3], hi[3];
  };
  void refresh_view();
  int32_t alloc_pair();
  int32_t split_node(int32_t id, int a, float mid, const Box& b, Box& l, Box& r);
  void subdivide(int32_t id, const Dists& dist, double n, const Box& b, int depth, double limit);
  void rebuild_node(const std::vector<int32_t>& oc, const std::vector<int32_t>& oa, const std::vector<float>& os,
                    const std::vector<Dists>& odist, const std::vector<uint64_t>& ocount, int32_t old, int32_t id,
                    const Box& b, int depth, double limit);

  Box box_;
  uint32_t learn_ = 0, learned_ = 0;
  float alpha_ = 0.5f;
  std::vector<int32_t> child_, axis_;
  std::vector<float> split_;
  std::vector<int32_t> leaf_dist_;  // per node, guide_classes distributions (GuideView::leaf_dist)
  int32_t depth_ = 1;
  std::vector<uint64_t> acc_;    // per node and class, guide_cells sums (leaves only)
  std::vector<uint64_t> count_;  // per node and class, records
  std::vector<float> func_, cond_, marg_;
  GuideView view_;
};

}  // namespace tuile
