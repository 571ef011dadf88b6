#include "plot.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

namespace diffdyn::cli {

bool RunPlotScript(const std::string& script, const std::vector<std::string>& args) {
  const std::string path = (PlotScriptsDir() / script).string();
  std::vector<std::string> argv_storage = {DIFFDYN_PYTHON, path};
  argv_storage.insert(argv_storage.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : argv_storage) argv.push_back(a.data());
  argv.push_back(nullptr);

  // fork + exec: no shell, so paths need no quoting.
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    setenv("MPLBACKEND", "Agg", 1);
    execv(DIFFDYN_PYTHON, argv.data());
    _exit(127);
  }
  int status = 0;
  if (pid < 0 || waitpid(pid, &status, 0) < 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::fprintf(stderr, "warning: plot script %s failed; the CSV data is written\n", path.c_str());
    return false;
  }
  return true;
}

}  // namespace diffdyn::cli
