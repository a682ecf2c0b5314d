// What `tuile profile` collects from a render: time per stage, trace events, and the
// packets traced (for the roofline replay).
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "lanes/packet.h"

namespace tuile {

// The stages of a tile, as profiled.
enum class Stage : int {
  generate = 0,
  intersect_camera,
  camera_hits,
  sample_lights,
  intersect_shadow,
  sample_bsdf,
  intersect_bounce,
  mis_weight,
  accumulate,
  media,  // scenes with media: free flights, interfaces, shadow transmittance (wave/media.h)
};
inline constexpr int stage_count = 10;
// Rows of the per-vertex profile of paths (vertex 1 .. profile_depths; deeper vertices
// count in the last row).
inline constexpr int profile_depths = 32;
const char* stage_name(Stage s);

struct TraceEvent {
  Stage stage;
  int tile;
  double start_us, dur_us;
  int thread = 0;
};

template <class P> struct RecordedPacket {
  P packet;
  alignas(64) int32_t valid[packet_width];  // (Embree's aligned loads of the mask)
};
// The packets one pass traces, in order (profile --roofline).
struct RayRecord {
  std::vector<RecordedPacket<RayHit16>> camera, bounce;
  std::vector<RecordedPacket<RayHit16>> bounce_emitters;  // bounce rays traced against the emitters alone
  std::vector<RecordedPacket<Ray16>> shadow;  // shadow rays, bounce visibility rays and escape rays
};

// Filled by Renderer::render when given: time per stage summed over threads, and
// optionally one trace event per stage call.
struct Profile {
  bool trace = false;
  size_t max_events = 2000000;  // per thread
  int threads = 1;
  double wall_seconds = 0;
  double stage_seconds[stage_count] = {};
  std::vector<TraceEvent> events;
  // paths (max_depth > 1), per vertex (index 0: the camera's hits): time per stage, the
  // shading points (live paths), the packets their rays filled, and the packets the tile's
  // lanes would have needed without compaction
  int depths = 0;  // rows used
  double depth_seconds[profile_depths][stage_count] = {};
  double depth_points[profile_depths] = {}, depth_packets[profile_depths] = {}, depth_lane_packets[profile_depths] = {};
  bool record_rays = false;  // keep the first pass's packets in `rays`
  RayRecord rays;
};

}  // namespace tuile
