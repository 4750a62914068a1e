#pragma once
// Ranks: the processes of one run started by an MPI launcher (`mpirun -np N terratiles ...`,
// Slurm's `srun`), or the one process of a plain run.
//
// A binary built with MPI (Open MPI from Debian, found by CMake) joins MPI only when a
// launcher started it (its variables are in the environment), so without mpirun it runs as a
// plain program and never touches MPI. Built without MPI, every run is one rank.
// Work spread over ranks is split by a rule every rank computes alike (block b on rank
// b mod N), and the ranks meet only where results come together (agree()).

#include <exception>

namespace terratiles {

class Ranks {
 public:
  // Joins MPI when an MPI launcher started this process; call once, first thing in main.
  static void start(int* argc, char*** argv);
  // Leaves MPI (when joined); call once before main returns.
  static void stop();
  static int rank();  // 0 .. size() - 1
  static int size();  // 1 without MPI
  // Every rank passes its own exit code (0: success) and gets the largest of them: where one
  // rank failed, all learn it at this meeting point instead of waiting for it for ever.
  static int agree(int my_exit_code);
  // agree() on whether this rank failed (`failure` is its exception, or null): rethrows it
  // here, or throws Error(Internal) "another rank failed" on the ranks that did not.
  static void meet(const std::exception_ptr& failure);
};

}  // namespace terratiles
