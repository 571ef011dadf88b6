// The exit-code contract on hostile input (DESIGN.md, "Exit codes"): bad input is
// one line `error: ...` naming the option or file with exit 2, before anything is
// written; no input file is ever replaced; no crash and no hang.
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>
#include <vector>

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "run_diffdyn.h"

namespace diffdyn {
namespace {

using testing::CommandResult;
using testing::ReadAll;
using testing::RunDiffdyn;
using testing::TempPath;

// Expects exit code 2 and one line "error: ..." that contains `needle`.
void ExpectBadInput(const CommandResult& r, const std::string& needle) {
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
  EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
  EXPECT_LE(r.err.size(), 320u) << r.err;
  EXPECT_NE(r.err.find(needle), std::string::npos) << "expected '" << needle << "' in: " << r.err;
}

// A small pendulum dataset and an abs-nn model trained on it, made once.
class Hardening : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    data_ = TempPath("hardening_pendulum.csv");
    model_ = TempPath("hardening_model.json");
    ASSERT_EQ(RunDiffdyn("collect --system pendulum --trajectories 2 --seconds 1 --seed 1 --quiet --out " + data_)
                  .exit_code,
              0);
    ASSERT_EQ(RunDiffdyn("train --data " + data_ + " --model abs-nn --hidden 4 --epochs 1 --quiet --out " + model_)
                  .exit_code,
              0);
  }
  static std::string data_, model_;
};
std::string Hardening::data_, Hardening::model_;

TEST_F(Hardening, DeeplyNestedJsonIsRefusedNotAStackOverflow) {
  const std::string deep = TempPath("hardening_deep.json");
  std::ofstream(deep) << std::string(100000, '[') << std::string(100000, ']');
  ExpectBadInput(RunDiffdyn("eval --quiet --data " + data_ + " --model " + deep), "nested deeper");
  std::string params;
  for (int i = 0; i < 100000; ++i) params += "{\"a\":";
  params += "1" + std::string(100000, '}');
  std::ofstream(deep, std::ios::trunc) << params;
  ExpectBadInput(RunDiffdyn("diagnose --quiet --model pendulum --measured " + data_ + " --params " + deep +
                            " --out " + TempPath("hardening_deep_out")),
                 "nested deeper");
  EXPECT_FALSE(std::filesystem::exists(TempPath("hardening_deep_out")));
}

TEST_F(Hardening, HugeOrWrappingCountsNameTheOption) {
  const std::string out = " --quiet --out " + TempPath("hardening_unused.json");
  ExpectBadInput(RunDiffdyn("train --data " + data_ + " --hidden 2147483647" + out), "--hidden");
  ExpectBadInput(RunDiffdyn("train --data " + data_ + " --hidden 4294967304" + out), "--hidden");
  ExpectBadInput(RunDiffdyn("train --data " + data_ + " --epochs 1000000000" + out), "--epochs");
  ExpectBadInput(RunDiffdyn("eval --quiet --data " + data_ + " --model pendulum --substeps 1000000000"),
                 "--substeps");
  ExpectBadInput(RunDiffdyn("push --quiet --model oracle --collision-substeps 1000000000"), "--collision-substeps");
  ExpectBadInput(RunDiffdyn("train --data " + data_ + " --threads -1" + out), "--threads");
  ExpectBadInput(RunDiffdyn("eval --quiet --data " + data_ + " --model pendulum --threads -1"), "--threads");
  ExpectBadInput(RunDiffdyn("push --quiet --model oracle --threads -1"), "--threads");
}

// A flag given a value (`--free=...`; a fuzz finding: an out-of-range number made
// CLI11's flag conversion throw std::out_of_range, reported as a runtime failure).
TEST_F(Hardening, FlagsTakeNoValues) {
  ExpectBadInput(RunDiffdyn("push --free=-99999999999999999999999"), "free was given a disallowed flag override");
  ExpectBadInput(RunDiffdyn("train --data " + data_ + " --json=7 --out " + TempPath("flag.json")), "json was given");
  EXPECT_EQ(RunDiffdyn("collect --system pendulum --trajectories 1 --seconds 1 --quiet --json=true --out " +
                       TempPath("flag_true.csv"))
                .exit_code,
            0);
}

TEST_F(Hardening, NonFiniteOptionValuesAreRefused) {
  ExpectBadInput(RunDiffdyn("diagnose --quiet --model pendulum --measured " + data_ +
                            " --rollout-horizon nan --out " + TempPath("hardening_nan")),
                 "--rollout-horizon");
  ExpectBadInput(RunDiffdyn("train --quiet --data " + data_ + " --lr inf --out " + TempPath("hardening_t.json")),
                 "--lr");
  ExpectBadInput(RunDiffdyn("control --quiet --system pendulum --horizon nan"), "--horizon");
  EXPECT_FALSE(std::filesystem::exists(TempPath("hardening_nan")));
}

TEST_F(Hardening, HugeParameterValuesAreRefused) {
  const std::string params = TempPath("hardening_params.json");
  std::ofstream(params) << R"({"g": 1e308})";
  ExpectBadInput(RunDiffdyn("diagnose --quiet --model pendulum --measured " + data_ + " --params " + params +
                            " --out " + TempPath("hardening_params_out")),
                 "outside");
  ExpectBadInput(RunDiffdyn("diagnose --quiet --model pendulum --measured " + data_ + " --param g=1e308 --out " +
                            TempPath("hardening_params_out")),
                 "outside");
  EXPECT_FALSE(std::filesystem::exists(TempPath("hardening_params_out")));
}

TEST_F(Hardening, ModelFileIntegersDoNotWrap) {
  // 4294967300 = 2^32 + 4 would read as hidden 4 through a 32-bit conversion.
  std::string text = ReadAll(model_);
  const std::size_t at = text.find("\"hidden\": 4");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 11, "\"hidden\": 4294967300");
  const std::string wrapped = TempPath("hardening_wrapped.json");
  std::ofstream(wrapped) << text;
  ExpectBadInput(RunDiffdyn("eval --quiet --data " + data_ + " --model " + wrapped), "'hidden'");
}

TEST_F(Hardening, AnOutputNeverReplacesAnInput) {
  const std::string copy = TempPath("hardening_same.csv");
  std::filesystem::copy_file(data_, copy, std::filesystem::copy_options::overwrite_existing);
  const std::string before = ReadAll(copy);
  ExpectBadInput(RunDiffdyn("train --quiet --epochs 1 --data " + copy + " --out " + copy), "--out");
  EXPECT_EQ(ReadAll(copy), before);
}

TEST_F(Hardening, DevicesFifosAndFoldersAreRefused) {
  ExpectBadInput(RunDiffdyn("train --quiet --epochs 1 --data " + data_ + " --out /dev/null"), "/dev/null");
  struct stat st {};
  ASSERT_EQ(stat("/dev/null", &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
  const std::string fifo = TempPath("hardening_fifo");
  std::filesystem::remove(fifo);
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  // Opening a FIFO for reading would block until a writer comes: refused first.
  ExpectBadInput(RunDiffdyn("eval --quiet --model pendulum --data " + fifo), "not a regular file");
  ExpectBadInput(RunDiffdyn("eval --quiet --data " + data_ + " --model " + fifo), "not a regular file");
  ExpectBadInput(RunDiffdyn("collect --quiet --system pendulum --trajectories 1 --out " + ::testing::TempDir()),
                 "not a regular file");
  std::filesystem::remove(fifo);
}

TEST_F(Hardening, ResultsThatCannotBeComputedAreErrorsNotNulls) {
  // Every JSON key of train and eval is a finite number: no split without a
  // validation sample, no data without a 4-step window.
  const std::string tiny = TempPath("hardening_tiny.csv");
  std::ofstream(tiny) << "t,q1,qd1,tau1\n0,0.1,0,0\n0.01,0.1,0,0.5\n0.02,0.1,0,0\n0.03,0.1,0,0.2\n";
  ExpectBadInput(RunDiffdyn("train --quiet --epochs 1 --val-fraction 0.000001 --data " + data_ + " --out " +
                            TempPath("hardening_t.json")),
                 "--val-fraction");
  ExpectBadInput(RunDiffdyn("eval --quiet --model pendulum --data " + tiny), "4-step window");
}

TEST_F(Hardening, AMegabyteOfInputIsNotEchoed) {
  const std::string wide = TempPath("hardening_wide.csv");
  std::ofstream(wide) << "t," << std::string(1 << 20, 'x') << "\n0,1\n";
  const CommandResult r = RunDiffdyn("eval --quiet --model pendulum --data " + wide);
  ExpectBadInput(r, wide);
}

// Ctrl-C during a long training run: the process dies of SIGINT promptly and leaves
// nothing in its output folder (no model file, no temporary file).
TEST_F(Hardening, CtrlCLeavesNoPartialFile) {
  const std::filesystem::path folder = TempPath("hardening_interrupted");
  std::filesystem::remove_all(folder);
  std::filesystem::create_directories(folder);
  const std::string out = (folder / "model.json").string();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int null = open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    execl(DIFFDYN_EXE, "diffdyn", "train", "--data", data_.c_str(), "--model", "abs-nn", "--hidden", "32",
          "--epochs", "1000000", "--out", out.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  ASSERT_EQ(kill(pid, SIGINT), 0);
  int status = 0;
  pid_t done = 0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while ((done = waitpid(pid, &status, WNOHANG)) == 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  if (done == 0) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
    FAIL() << "train did not end within 20 s of SIGINT";
  }
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGINT) << "status " << status;
  std::vector<std::string> left;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) left.push_back(entry.path().string());
  EXPECT_TRUE(left.empty()) << left.front();
}

}  // namespace
}  // namespace diffdyn
