// The sweep scheduler over Open MPI ranks (solvers/sweep_mpi.h).
#include "diffdyn/solvers/sweep_mpi.h"

#include <mpi.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstdio>
#include <exception>
#include <optional>
#include <string>
#include <thread>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {
namespace {

// Message tags: a worker's request (carrying its last result, or "{}"), and rank
// 0's answer (a task index, or -1 for "no more").
constexpr int kTagRequest = 1;
constexpr int kTagTask = 2;

// Waits (blocked) for the child `pid`; returns its wait status.
int WaitFor(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw std::runtime_error("sweep: waiting for a task failed");
  }
  return status;
}

// A result as the message a worker sends to rank 0.
std::string Encode(int index, const SweepResult& r) {
  return nlohmann::json{{"index", index}, {"exit_code", r.exit_code}, {"summary", r.summary}, {"seconds", r.seconds}}
      .dump();
}

// Rank > 0: ask, run, report, until rank 0 says there is no more.
void Work(const std::filesystem::path& executable, const SweepQueue& queue) {
  std::string message = "{}";
  for (;;) {
    MPI_Send(message.data(), static_cast<int>(message.size()), MPI_CHAR, 0, kTagRequest, MPI_COMM_WORLD);
    int index = -1;
    MPI_Recv(&index, 1, MPI_INT, 0, kTagTask, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (index < 0) return;
    const SweepTask& task = queue.Tasks().at(static_cast<std::size_t>(index));
    const std::filesystem::path dir = queue.Folder().TaskDir(index);
    const RunningTask running = StartSweepTask(executable, task, dir);
    message = Encode(index, FinishSweepTask(running, WaitFor(running.pid), dir));
  }
}

// Rank 0: answers one pending request if there is one; returns whether it did.
// Decrements `active` when it tells a worker to stop.
bool AnswerRequest(SweepQueue& queue, int& active) {
  int arrived = 0;
  MPI_Status status;
  MPI_Iprobe(MPI_ANY_SOURCE, kTagRequest, MPI_COMM_WORLD, &arrived, &status);
  if (!arrived) return false;
  int bytes = 0;
  MPI_Get_count(&status, MPI_CHAR, &bytes);
  std::string text(static_cast<std::size_t>(bytes), '\0');
  MPI_Recv(text.data(), bytes, MPI_CHAR, status.MPI_SOURCE, kTagRequest, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  const nlohmann::json j = nlohmann::json::parse(text);
  if (j.contains("index")) {
    SweepResult r;
    r.exit_code = j.at("exit_code").get<int>();
    r.summary = j.at("summary");
    r.seconds = j.at("seconds").get<double>();
    queue.Finish(j.at("index").get<int>(), std::move(r));
  }
  const int next = queue.Next().value_or(-1);
  if (next < 0) --active;
  MPI_Send(&next, 1, MPI_INT, status.MPI_SOURCE, kTagTask, MPI_COMM_WORLD);
  return true;
}

// Rank 0: runs tasks itself and serves the other ranks until all have stopped.
void Coordinate(const std::filesystem::path& executable, SweepQueue& queue, int ranks) {
  std::optional<RunningTask> own;
  int active = ranks - 1;  // workers not yet told to stop
  for (;;) {
    if (!own) {
      if (const std::optional<int> next = queue.Next()) {
        own = StartSweepTask(executable, queue.Tasks()[static_cast<std::size_t>(*next)],
                             queue.Folder().TaskDir(*next));
      }
    } else {
      int status = 0;
      if (::waitpid(own->pid, &status, WNOHANG) == own->pid) {
        queue.Finish(own->index, FinishSweepTask(*own, status, queue.Folder().TaskDir(own->index)));
        own.reset();
        continue;
      }
    }
    if (AnswerRequest(queue, active)) continue;
    if (!own && active == 0) return;
    std::this_thread::sleep_for(kMpiPollInterval);
  }
}

}  // namespace

MpiSweepOutcome RunSweepMpi(const std::filesystem::path& executable, SweepQueue& queue) {
  MPI_Init(nullptr, nullptr);
  MpiSweepOutcome outcome;
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &outcome.ranks);
  outcome.coordinator = rank == 0;
  try {
    if (outcome.coordinator) Coordinate(executable, queue, outcome.ranks);
    else Work(executable, queue);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: sweep (MPI rank %d): %s\n", rank, e.what());
    MPI_Abort(MPI_COMM_WORLD, 1);
  }
  MPI_Finalize();
  return outcome;
}

}  // namespace diffdyn
