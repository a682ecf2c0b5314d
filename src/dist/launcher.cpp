// The launcher's environment: how many ranks, which one this is (no MPI needed to ask).
#include <cstdlib>
#include <string>

#include "dist/dist.h"

namespace tuile {

namespace {
int env_int(std::initializer_list<const char*> names, int fallback) {
  for (const char* n : names)
    if (const char* v = std::getenv(n)) {
      try {
        return std::stoi(v);
      } catch (...) {
      }
    }
  return fallback;
}
}  // namespace

int launcher_size() { return env_int({"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"}, 1); }
int launcher_rank() { return env_int({"OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"}, 0); }

}  // namespace tuile
