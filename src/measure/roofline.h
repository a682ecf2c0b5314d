// The roofline's bound: the packets a profiled render traced, replayed through Embree
// alone with the same packets and flags.
#pragma once
#include "accel/embree.h"
#include "render/profile.h"

namespace tuile {

// Traces the recorded packets through Embree alone, in the same packets and flags, with
// the given thread count; returns the seconds taken (the roofline's bound).
double replay_rays(const Accel& accel, const RayRecord& rays, int threads);
// The same rays as pointer-SoA streams (rtcIntersectNp), one stream per tile's packets;
// the time includes a copy of each stream, as the packet replay includes its copies.
double replay_rays_stream(const Accel& accel, const RayRecord& rays, int threads);

}  // namespace tuile
