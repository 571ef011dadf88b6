// Sweeps over Open MPI ranks (built when CMake finds MPI; DIFFDYN_HAVE_MPI).
//
// Under `mpirun -np N diffdyn sweep ...` every rank expands the same spec. Rank 0
// coordinates: it hands out task indices one at a time to the ranks that ask,
// records their results (result.json, results.csv) and runs tasks itself
// between messages. It waits without spinning: its own task's child is checked
// with waitpid(WNOHANG) and messages with MPI_Iprobe, and when neither has
// anything it sleeps kMpiPollInterval. The other ranks ask for a task, run it as
// a child process (blocked in waitpid), send back its exit code and summary, and
// ask again until rank 0 answers "no more".
//
// Task folders are written by the rank that runs the task: on a cluster the
// sweep's --out folder must be on a file system every node sees.
//
//   diffdyn::SweepQueue queue(tasks, diffdyn::SweepFolder("out"));
//   const diffdyn::MpiSweepOutcome o = diffdyn::RunSweepMpi(exe, queue);
//   if (o.coordinator) diffdyn::WriteSweepResults(spec, tasks, queue.Results(), "out/results.csv");
#pragma once

#include <chrono>
#include <filesystem>

#include "diffdyn/solvers/sweep.h"

namespace diffdyn {

/// How often an idle coordinator looks for messages and its own task's end.
inline constexpr std::chrono::milliseconds kMpiPollInterval{2};

/// What RunSweepMpi did on this rank.
struct MpiSweepOutcome {
  /// True on rank 0, whose queue holds every result afterwards.
  bool coordinator = false;
  /// Number of ranks (MPI_COMM_WORLD's size).
  int ranks = 1;
};

/// Initialises MPI, runs `queue`'s pending tasks over all ranks (see the file
/// comment) and finalises MPI. A failure on any rank (an exception) prints
/// one line "error: ..." and aborts every rank with exit code 1, so no rank waits
/// forever for a dead coordinator.
MpiSweepOutcome RunSweepMpi(const std::filesystem::path& executable, SweepQueue& queue);

}  // namespace diffdyn
