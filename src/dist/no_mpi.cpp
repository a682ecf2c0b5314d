// A build without MPI: distributed renders are refused with a message saying why.
#include <stdexcept>

#include "dist/dist.h"

namespace tuile {

bool mpi_available() { return false; }
int run_render_distributed(const RenderFlags&) {
  throw std::invalid_argument("started with several ranks, but this tuile was built without MPI "
                              "(install libopenmpi-dev and rebuild)");
}
int run_bench_distributed(const BenchFlags&) { return run_render_distributed(RenderFlags{}); }

}  // namespace tuile
