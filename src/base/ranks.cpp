#include "src/base/ranks.h"

#include <cstdlib>
#include <string>

#if defined(TERRATILES_WITH_MPI)
#include <mpi.h>
#endif

#include "src/base/error.h"

namespace terratiles {
namespace {

int g_rank = 0;
int g_size = 1;
bool g_joined = false;

// Whether an MPI launcher started this process: Open MPI's mpirun, PMIx (Open MPI 4+, Slurm)
// or PMI-1/2 (Slurm's srun, MPICH's Hydra) put these in the environment.
bool launchedByMpi() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"}) {
    if (std::getenv(name)) return true;
  }
  return false;
}

}  // namespace

void Ranks::start(int* argc, char*** argv) {
#if defined(TERRATILES_WITH_MPI)
  if (g_joined || !launchedByMpi()) return;
  int provided = 0;
  MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);  // MPI calls from the main thread only
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  g_joined = true;
#else
  (void)argc;
  (void)argv;
  (void)launchedByMpi;
#endif
}

void Ranks::stop() {
#if defined(TERRATILES_WITH_MPI)
  if (g_joined) MPI_Finalize();
  g_joined = false;
#endif
}

int Ranks::rank() { return g_rank; }
int Ranks::size() { return g_size; }

int Ranks::agree(int my_exit_code) {
#if defined(TERRATILES_WITH_MPI)
  if (g_joined && g_size > 1) {
    int largest = my_exit_code;
    MPI_Allreduce(&my_exit_code, &largest, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    return largest;
  }
#endif
  return my_exit_code;
}

void Ranks::meet(const std::exception_ptr& failure) {
  if (agree(failure ? 1 : 0) == 0) return;
  if (failure) std::rethrow_exception(failure);
  throw Error(ErrorCode::Internal, "rank " + std::to_string(rank()) + " stops: another rank failed (its error is above)");
}

}  // namespace terratiles
