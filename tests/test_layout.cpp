// SampleLayout hands every use of random numbers its own dimension pairs: no two purposes
// (or depths) share one, and depth 0 keeps the pairs images were rendered with before
// the layout existed (camera 0, choice 1, BSDF samples 2.., light samples two each after).
#include <gtest/gtest.h>

#include <map>
#include <string>

#include "sample/layout.h"

using namespace tuile;

TEST(SampleLayout, PairsAreDistinctAcrossPurposesAndDepths) {
  for (uint32_t M : {1u, 2u, 5u})
    for (uint32_t N : {1u, 3u, 101u}) {
      const SampleLayout L{M, N};
      std::map<uint32_t, std::string> owner;
      auto claim = [&](uint32_t pair, const std::string& what) {
        const auto [it, fresh] = owner.emplace(pair, what);
        EXPECT_TRUE(fresh) << "pair " << pair << " of " << what << " already belongs to " << it->second;
      };
      claim(SampleLayout::camera, "camera");
      for (uint32_t d = 0; d < 4; ++d) {
        const std::string at = " depth " + std::to_string(d);
        claim(L.technique_choice(d), "choice" + at);
        for (uint32_t m = 0; m < M; ++m) {
          claim(L.bsdf(m, d), "bsdf " + std::to_string(m) + at);
          claim(L.bsdf_lobe(m, d), "lobe " + std::to_string(m) + at);
        }
        for (uint32_t j = 0; j < N; ++j) {
          claim(L.light_pick(j, d), "pick " + std::to_string(j) + at);
          claim(L.light_point(j, d), "point " + std::to_string(j) + at);
        }
        claim(L.russian_roulette(d), "roulette" + at);
      }
      // dense: the pairs of depths 0..3 are exactly 0 .. their count - 1
      EXPECT_EQ(owner.rbegin()->first + 1, owner.size());
      // depth 0 as before the layout
      EXPECT_EQ(L.technique_choice(), 1u);
      EXPECT_EQ(L.bsdf(0), 2u);
      EXPECT_EQ(L.bsdf(M - 1), 1 + M);
      EXPECT_EQ(L.light_pick(0), 2 + M);
      EXPECT_EQ(L.light_point(N - 1), 2 + M + 2 * (N - 1) + 1);
      EXPECT_EQ(L.bsdf_lobe(0), 2 + M + 2 * N);  // the lobe choices after the pairs above
      EXPECT_EQ(L.russian_roulette(0), 2 + 2 * M + 2 * N);  // then Russian roulette
    }
}
