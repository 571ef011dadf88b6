// diffdyn: the command-line tool (the commands and their parsing are in the
// diffdyn_cli library, see command.h).
#include <unistd.h>

#include <csignal>

#include <glog/logging.h>

#include "command.h"
#include "diffdyn/models/io.h"

namespace {

// Ctrl-C or a kill: remove a half-written temporary file, then die of the signal.
extern "C" void OnTerminate(int signal_number) {
  if (const char* tmp = diffdyn::TemporaryFileInProgress().load()) ::unlink(tmp);
  std::signal(signal_number, SIG_DFL);
  std::raise(signal_number);
}

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGINT, OnTerminate);
  std::signal(SIGTERM, OnTerminate);
  // Ceres logs through glog; diffdyn reports failures itself, as one line.
  FLAGS_minloglevel = google::GLOG_FATAL;
  FLAGS_logtostderr = true;
  google::InitGoogleLogging(argv[0]);
  return diffdyn::cli::Run(argc, argv);
}
