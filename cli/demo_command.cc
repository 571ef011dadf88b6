// diffdyn demo: the end-to-end pipeline that exists so far, with a report.
//
// Stage 1 (system identification through the integrator): a damped pendulum is
// "measured" (simulated with a fine fixed-step integrator, plus seeded sensor noise),
// then its gravity g and damping b are fitted with Ceres through dopri5 on Jets, with
// standard errors. The report compares the estimates with the truth.
#include <filesystem>
#include <fstream>
#include <vector>

#include <fmt/core.h>
#include <fmt/ostream.h>

#include "command.h"
#include "diffdyn/autodiff_ode/io.h"
#include "diffdyn/autodiff_ode/progress.h"
#include "diffdyn/autodiff_ode/random.h"
#include "diffdyn/solvers/trajectory_fit.h"
#include "plot.h"

namespace diffdyn::cli {
namespace {

struct DemoOptions {
  CommonOptions common;
  std::string out = "demo-output";
  bool quick = false;
};

// m l^2 qdd + m g l sin q + b qd = 0 with m = 1 kg, l = 0.5 m; theta = (g, b).
struct DampedPendulum {
  static constexpr double kLength = 0.5;
  template <typename T>
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double, const T* theta) const {
    using std::sin;
    dxdt[0] = x[1];
    dxdt[1] = -theta[0] / kLength * sin(x[0]) - theta[1] / (kLength * kLength) * x[1];
  }
};

struct PendulumStage {
  Eigen::Vector2d truth{9.81, 0.02};
  Eigen::Vector2d initial{7.0, 0.0};
  std::vector<MeasuredTrajectory> data;
  TrajectoryFitResult fit;
};

// Simulates `count` trajectories with rk4 at 1e-4 s (independent of the fit's dopri5)
// and adds Gaussian noise (0.01 rad, 0.05 rad/s) at 50 Hz.
std::vector<MeasuredTrajectory> MeasurePendulum(const Eigen::Vector2d& truth, int count,
                                                double duration, Rng& rng) {
  std::vector<MeasuredTrajectory> data;
  const int samples = static_cast<int>(duration * 50) + 1;
  for (int k = 0; k < count; ++k) {
    MeasuredTrajectory traj;
    Eigen::VectorXd x(2);
    x << Uniform(rng, 0.5, 2.5), Uniform(rng, -1.0, 1.0);
    traj.states.resize(2, samples);
    for (int i = 0; i < samples; ++i) traj.times.push_back(i / 50.0);
    OdeOptions fine;
    fine.method = Method::kRk4Classic;
    fine.dt = 1e-4;
    auto system = [&](const VectorX<double>& s, VectorX<double>& dsdt, double t) {
      DampedPendulum{}(s, dsdt, t, truth.data());
    };
    IntegrateTimes(system, x, traj.times, fine, [&](int i, double, const VectorX<double>& s) {
      traj.states(0, i) = s[0] + 0.01 * StandardNormal(rng);
      traj.states(1, i) = s[1] + 0.05 * StandardNormal(rng);
    });
    data.push_back(std::move(traj));
  }
  return data;
}

// Writes measured, initial-guess and fitted angle trajectories for the plot.
void WritePendulumCsv(const std::filesystem::path& path, const PendulumStage& stage) {
  WriteFileAtomically(path, [&](std::ostream& out) {
    out << "trajectory,t,q_measured,q_initial,q_fitted\n";
    for (std::size_t k = 0; k < stage.data.size(); ++k) {
      const auto& d = stage.data[k];
      Eigen::MatrixXd predicted[2] = {d.states, d.states};
      const Eigen::Vector2d thetas[2] = {stage.initial, stage.fit.params};
      for (int m = 0; m < 2; ++m) {
        Eigen::VectorXd x = d.states.col(0);
        auto system = [&](const VectorX<double>& s, VectorX<double>& dsdt, double t) {
          DampedPendulum{}(s, dsdt, t, thetas[m].data());
        };
        IntegrateTimes(system, x, d.times, OdeOptions{},
                       [&](int i, double, const VectorX<double>& s) { predicted[m].col(i) = s; });
      }
      for (std::size_t i = 0; i < d.times.size(); ++i) {
        fmt::print(out, "{},{:.4f},{:.6f},{:.6f},{:.6f}\n", k, d.times[i], d.states(0, i),
                   predicted[0](0, i), predicted[1](0, i));
      }
    }
  });
}

void RunDemo(const DemoOptions& options) {
  namespace fs = std::filesystem;
  DIFFDYN_CHECK(!options.out.empty(), "--out: empty directory name");
  std::error_code ec;
  fs::create_directories(options.out, ec);
  DIFFDYN_CHECK(!ec && fs::is_directory(options.out), "--out ", options.out,
                ": cannot create directory: ", ec.message());
  const fs::path out(options.out);
  ProgressBar bar("demo", 2, !options.common.quiet);

  // Stage 1: measure, then fit through dopri5 on Jets.
  Rng rng(options.common.seed);
  PendulumStage pendulum;
  pendulum.data = MeasurePendulum(pendulum.truth, options.quick ? 2 : 4,
                                  options.quick ? 3.0 : 6.0, rng);
  bar.Update(1, "fitting the pendulum");
  TrajectoryFitOptions fit_options;
  fit_options.ode.method = Method::kDopri5;
  fit_options.ode.abs_tol = fit_options.ode.rel_tol = 1e-9;
  pendulum.fit = FitTrajectoryParameters<2>(DampedPendulum{}, pendulum.data, pendulum.initial,
                                            fit_options);
  WritePendulumCsv(out / "pendulum_fit.csv", pendulum);
  const bool plotted = RunPlotScript(
      "demo_pendulum_fit.py", {(out / "pendulum_fit.csv").string(), (out / "pendulum_fit.png").string()});
  bar.Update(2);
  bar.Finish();

  // The report.
  const auto& fit = pendulum.fit;
  const char* names[2] = {"gravity g (m/s^2)", "damping b (N m s/rad)"};
  nlohmann::json params = nlohmann::json::array();
  std::string table;
  for (int i = 0; i < 2; ++i) {
    const double z = std::abs(fit.params[i] - pendulum.truth[i]) / fit.standard_errors[i];
    params.push_back({{"name", names[i]}, {"truth", pendulum.truth[i]}, {"initial", pendulum.initial[i]},
                      {"fitted", fit.params[i]}, {"stderr", fit.standard_errors[i]}, {"z", z}});
    table += fmt::format("| {} | {:.4g} | {:.4g} | {:.5g} | {:.2g} | {:.2f} |\n", names[i],
                         pendulum.truth[i], pendulum.initial[i], fit.params[i],
                         fit.standard_errors[i], z);
  }
  WriteFileAtomically(out / "report.md", [&](std::ostream& s) {
    fmt::print(s, "# diffdyn demo\n\n## 1. Identifying a damped pendulum through the integrator\n\n");
    fmt::print(s,
               "{} trajectories of a damped pendulum (m = 1 kg, l = 0.5 m) were simulated with "
               "classic RK4 at 0.1 ms and sampled at 50 Hz with noise of 0.01 rad and 0.05 rad/s "
               "(seed {}). Gravity and damping were then fitted by Ceres (Levenberg-Marquardt) "
               "through dopri5 (tolerance 1e-9) running on Jets, so the Jacobian of every "
               "prediction is exact; standard errors from sigma^2 (J^T J)^-1.\n\n",
               pendulum.data.size(), options.common.seed);
    fmt::print(s, "| parameter | truth | initial | fitted | std. error | abs(error)/stderr |\n");
    fmt::print(s, "|---|---|---|---|---|---|\n{}\n", table);
    fmt::print(s, "RMS residual {:.4g} -> {:.4g} over {} residuals in {} iterations ({}).\n\n",
               fit.initial_rms, fit.final_rms, fit.num_residuals, fit.iterations, fit.summary);
    if (plotted) fmt::print(s, "![measured and fitted angles](pendulum_fit.png)\n");
  });

  const nlohmann::json summary = {{"out", out.string()},
                                  {"pendulum_fit", {{"params", params},
                                                    {"initial_rms", fit.initial_rms},
                                                    {"final_rms", fit.final_rms},
                                                    {"converged", fit.converged}}}};
  if (options.common.json) {
    PrintJson(summary);
    return;
  }
  fmt::print("diffdyn demo: pendulum identified through dopri5 on Jets\n{}", table);
  fmt::print("report: {}\n", (out / "report.md").string());
}

}  // namespace

void RegisterDemoCommand(CLI::App& app) {
  auto* command = app.add_subcommand("demo", "Run the end-to-end pipeline that exists so far");
  auto options = std::make_shared<DemoOptions>();
  AddCommonOptions(command, options->common);
  command->add_option("--out", options->out, "Directory for the report, CSVs and PNGs");
  command->add_flag("--quick", options->quick, "A smaller run (used by the tests)");
  command->callback([options] { RunDemo(*options); });
}

}  // namespace diffdyn::cli
