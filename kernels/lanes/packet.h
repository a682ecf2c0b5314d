// Ray packets in the exact memory layout Embree 3 reads for rtcIntersect16 /
// rtcOccluded16 (RTCRayHit16, RTCRay16), so the intersect stage copies nothing.
// src/embree.cpp static_asserts that the layouts match.
#pragma once
#include <algorithm>
#include <cstdint>

#include "lanes/simd.h"

namespace tuile {

inline constexpr int packet_width = 16;
// Counts rounded up to whole packets (and SIMD batches): stages run whole packets, the
// lanes past the count padded with harmless values that are never traced.
inline constexpr int div_up(int n, int d) { return (n + d - 1) / d; }
inline constexpr int packets_for(int lanes) { return div_up(lanes, packet_width); }
inline constexpr int packet_padded(int lanes) { return packets_for(lanes) * packet_width; }
inline constexpr uint32_t invalid_id = 0xffffffffu;

struct alignas(64) Ray16 {
  float org_x[16], org_y[16], org_z[16], tnear[16];
  float dir_x[16], dir_y[16], dir_z[16], time[16];
  float tfar[16];
  uint32_t mask[16], id[16], flags[16];
};

struct alignas(64) RayHit16 {
  Ray16 ray;
  float Ng_x[16], Ng_y[16], Ng_z[16], u[16], v[16];
  uint32_t primID[16], geomID[16], instID[1][16];
};

// A ray field (e.g. &Ray16::org_x) of a ray packet or of a hit packet's ray.
inline float* field_of(Ray16& p, float (Ray16::*f)[16]) noexcept { return p.*f; }
inline float* field_of(RayHit16& p, float (Ray16::*f)[16]) noexcept { return p.ray.*f; }

// Stores lanes [k, k + width) of one ray field of an array of packets (Ray16 or RayHit16),
// packet k / 16 at lane k % 16; a lane type wider than a packet continues into the next.
template <class P, class T> inline void store_field(P* packets, float (Ray16::*field)[16], int k, const T& v) noexcept {
  if constexpr (std::is_same_v<T, float>) field_of(packets[k / packet_width], field)[k % packet_width] = v;
  else if constexpr (lane_traits<T>::width <= packet_width) store(field_of(packets[k / packet_width], field) + k % packet_width, v);
  else {
    store_field(packets, field, k, v.a);
    store_field(packets, field, k + lane_traits<T>::width / 2, v.b);
  }
}

// The fields of a packet that stay the same for every query: every ray starts at t = 0 at
// time 0, enabled, with no id and no flags. Embree only reads them, so TileBuffers sets
// them once.
inline void reset_query_fields(Ray16& r) noexcept {
  std::fill_n(r.tnear, packet_width, 0.f);
  std::fill_n(r.time, packet_width, 0.f);
  std::fill_n(r.mask, packet_width, 0xffffffffu);
  std::fill_n(r.id, packet_width, 0u);
  std::fill_n(r.flags, packet_width, 0u);
}
inline void reset_query_fields(RayHit16& p) noexcept {
  reset_query_fields(p.ray);
  std::fill_n(p.instID[0], packet_width, invalid_id);
}
// No hit yet: Embree writes geomID only where a ray hits, so it is reset before every query.
inline void reset_hit(RayHit16& p) noexcept { std::fill_n(p.geomID, packet_width, invalid_id); }

}  // namespace tuile
