// Rendering over several processes with MPI: `mpirun -n K tuile render ...` (and bench).
// Rank 0 hands out units of work (a pass of the render over a block of tiles) as ranks
// ask for them, the other ranks render them and send back the tiles' sums in double, and
// rank 0 adds each block's passes in order, so the image has the bits of a single-process
// render with the same options, for any K and any assignment of units.
//
// MPI is optional: without it (or when a process was not started by an MPI launcher)
// tuile runs as one process exactly as before; MPI is initialised only under a launcher.
#pragma once
#include <string>

#include "app/cli.h"
#include "app/commands.h"

namespace tuile {

// From the launcher's environment (Open MPI, or PMI / PMIx launchers), without MPI: the
// number of ranks (1 when not launched with ranks) and this process's rank (0).
int launcher_size();
int launcher_rank();
// Whether this build can render over MPI.
bool mpi_available();

// `tuile render` / `tuile bench` over all ranks (launcher_size() > 1, mpi_available()).
int run_render_distributed(const RenderFlags& f);
int run_bench_distributed(const BenchFlags& f);

}  // namespace tuile
