// diffdyn hjb: a control task's value function by HJB residual minimisation with a
// discount homotopy (solvers/hjb.h), saved as a model file of kind "value".
//
//   diffdyn hjb --system pendulum --out value.json [--stages 6] [--polish-stages 2]
//               [--epochs 40] [--samples 51200] [--hidden 96] [--layers 2] [--lr 1e-3]
//               [--batch 256] [--rho-start 5] [--rho-final 0.0862] [--threads 0] [--seed 0]
//               [--candidates 1] [--validation-starts 40] [--goal-anchor 0]
//               [--rollout-stages 3] [--rollout-starts 64] [--rollout-weight 10]
//               [--rollout-epochs 20] [--rollout-lr 1e-4]
//   diffdyn control --system pendulum --controller hjb --model value.json --starts 300 --seed 1
//
// Each stage prints its discount, held-out residual and wall time (unless --quiet).
// With --candidates K, K value functions are trained from seeds S .. S + K - 1 and the
// one whose policy costs least from --validation-starts validation starts is kept
// (LearnTaskValue). The file is written once, at the end, atomically.
#include <chrono>
#include <cmath>
#include <memory>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/solvers/hjb.h"

namespace diffdyn::cli {
namespace {

struct HjbCommandOptions {
  CommonOptions common;
  std::string system = "pendulum";
  std::string out;
  HjbOptions hjb;
  int hidden = 96;
  int layers = 2;
};

void RunHjb(HjbCommandOptions o) {
  // Validate everything before the work starts.
  const ControlTask task = ControlTaskByName(o.system);
  o.hjb.hidden.assign(static_cast<std::size_t>(o.layers), o.hidden);
  o.hjb.seed = o.common.seed;
  o.hjb.train.seed = o.common.seed;
  o.hjb.Validate();
  const auto start = std::chrono::steady_clock::now();
  nlohmann::json stages = nlohmann::json::array(), candidates = nlohmann::json::array();
  int candidate = 0;
  const auto on_stage = [&](const HjbStageReport& r) {
    stages.push_back({{"candidate", candidate}, {"rho", r.rho}, {"learning_rate", r.learning_rate},
                      {"epochs", r.result.epochs.size()}, {"residual", r.result.final_val_loss},
                      {"seconds", r.seconds}});
    if (!o.common.quiet) {
      fmt::print(stderr, "hjb: {}stage {}/{}: rho {:.4g}, lr {:.2g}, mean squared residual {:.4g} (held out), "
                 "{:.1f} s\n", o.hjb.candidates > 1 ? fmt::format("candidate {}/{}, ", candidate + 1,
                                                                   o.hjb.candidates) : "",
                 r.stage + 1, r.stages, r.rho, r.learning_rate, r.result.final_val_loss, r.seconds);
    }
  };
  const auto on_candidate = [&](const HjbCandidateReport& r) {
    candidates.push_back({{"seed", r.seed}, {"successes", r.successes}, {"mean_cost", r.mean_cost},
                          {"residual", r.residual}});
    if (!o.common.quiet && o.hjb.candidates > 1) {
      fmt::print(stderr, "hjb: candidate {}/{} (seed {}): {}/{} validation starts swung up, mean cost {:.3f}\n",
                 r.candidate + 1, o.hjb.candidates, r.seed, r.successes, o.hjb.validation_starts, r.mean_cost);
    }
    ++candidate;
  };
  int kept = 0;
  const ValueFunction value = LearnTaskValue(task, o.hjb, on_stage, on_candidate, &kept);
  const double residual = candidates[static_cast<std::size_t>(kept)]["residual"].get<double>();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const nlohmann::json provenance = {{"command", "diffdyn hjb"},         {"system", o.system},
                                     {"seed", o.common.seed},           {"samples", o.hjb.samples},
                                     {"epochs", o.hjb.train.epochs},    {"lr", o.hjb.train.learning_rate},
                                     {"batch", o.hjb.train.batch_size}, {"rho_start", o.hjb.rho_start},
                                     {"rho_final", o.hjb.rho_final},    {"rollout_stages", o.hjb.rollout_stages},
                                     {"rollout_weight", o.hjb.rollout_weight}, {"stages", stages},
                                     {"candidates", candidates}};
  SaveValueFunction(o.out, value, o.system, provenance, {{"final_residual", residual}, {"seconds", seconds}});
  const int total = o.hjb.stages + o.hjb.polish_stages + o.hjb.rollout_stages;
  if (o.common.json) {
    PrintJson({{"model_path", o.out},
               {"stages", total},
               {"rho_final", o.hjb.rho_final},
               {"seconds", seconds},
               {"final_residual", residual},
               {"system", o.system},
               {"parameters", value.net().num_parameters()},
               {"candidates", candidates}});
    return;
  }
  fmt::print("value function of the {} task ({} parameters): {} stages, rho {:.4g} -> {:.4g}, "
             "mean squared HJB residual {:.4g} (held out), {:.1f} s\n",
             o.system, value.net().num_parameters(), total, o.hjb.rho_start, o.hjb.rho_final, residual, seconds);
  fmt::print("saved {}\n", o.out);
}

}  // namespace

void RegisterHjbCommand(CLI::App& app) {
  auto o = std::make_shared<HjbCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "hjb", "Learn a control task's value function (HJB residual, discount homotopy) as a feedback policy");
  AddCommonOptions(command, o->common);
  command->add_option("--system", o->system, "Control task: pendulum or cartpole")->capture_default_str();
  command->add_option("--out", o->out, "Value-function file to write (kind value)")
      ->check(OutputPath())
      ->required();
  command->add_option("--stages", o->hjb.stages, "Homotopy stages, rho geometric from --rho-start to --rho-final")
      ->check(Bounded(1, 1000))
      ->capture_default_str();
  command->add_option("--polish-stages", o->hjb.polish_stages,
                      "Stages at --rho-final after the homotopy, the learning rate divided by 3 each")
      ->check(Bounded(0, 1000))
      ->capture_default_str();
  command->add_option("--rho-start", o->hjb.rho_start, "First discount (1/s)")
      ->check(Bounded(1e-6, 1e6))
      ->capture_default_str();
  command->add_option("--rho-final", o->hjb.rho_final, "Last discount (1/s), at most --rho-start")
      ->check(Bounded(1e-6, 1e6))
      ->capture_default_str();
  command->add_option("--samples", o->hjb.samples, "Uniform states over the task's domain, drawn per stage")
      ->check(Bounded(2, 1e7))
      ->capture_default_str();
  command->add_option("--goal-anchor", o->hjb.goal_anchor_weight,
                      "Weight of the goal's LQR cost-to-go as value anchors in each stage's loss (0: none)")
      ->check(Bounded(0, 1e6))
      ->capture_default_str();
  command->add_option("--rollout-stages", o->hjb.rollout_stages,
                      "Stages after the polish whose loss also holds V to the policy's own discounted costs-to-go")
      ->check(Bounded(0, 1000))
      ->capture_default_str();
  command->add_option("--rollout-starts", o->hjb.rollout_starts, "Policy runs per rollout stage")
      ->check(Bounded(1, 100000))
      ->capture_default_str();
  command->add_option("--rollout-weight", o->hjb.rollout_weight, "Weight of the rollout stages' value targets")
      ->check(Bounded(0, 1e6))
      ->capture_default_str();
  command->add_option("--rollout-epochs", o->hjb.rollout_epochs, "Adam epochs per rollout stage")
      ->check(Bounded(1, 1e6))
      ->capture_default_str();
  command->add_option("--rollout-lr", o->hjb.rollout_learning_rate, "Adam learning rate of the rollout stages")
      ->check(Bounded(1e-12, 10))
      ->capture_default_str();
  command->add_option("--epochs", o->hjb.train.epochs, "Adam epochs per stage")
      ->check(Bounded(1, 1e6))
      ->capture_default_str();
  command->add_option("--lr", o->hjb.train.learning_rate, "Adam learning rate of the homotopy stages")
      ->check(Bounded(1e-12, 10))
      ->capture_default_str();
  command->add_option("--batch", o->hjb.train.batch_size, "Mini-batch size")
      ->check(Bounded(1, 1e7))
      ->capture_default_str();
  command->add_option("--hidden", o->hidden, "Width of the hidden layers (tanh)")
      ->check(Bounded(1, 4096))
      ->capture_default_str();
  command->add_option("--layers", o->layers, "Number of hidden layers")
      ->check(Bounded(1, 16))
      ->capture_default_str();
  command->add_option("--candidates", o->hjb.candidates,
                      "Value functions trained from seeds S, S + 1, ...; the one whose policy costs least from "
                      "the validation starts is kept")
      ->check(Bounded(1, 1000))
      ->capture_default_str();
  command->add_option("--validation-starts", o->hjb.validation_starts,
                      "Validation starts per candidate (seeded apart from control's starts)")
      ->check(Bounded(1, 100000))
      ->capture_default_str();
  command->add_option("--threads", o->hjb.train.threads, "Threads (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256))
      ->capture_default_str();
  command->callback([o] { RunHjb(*o); });
}

}  // namespace diffdyn::cli
