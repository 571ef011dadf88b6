#include "diffdyn/solvers/diagnosis/candidates.h"

#include <algorithm>
#include <cmath>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {
namespace {

bool MovesWithVelocity(EffectKind kind) {
  return kind == EffectKind::kViscous || IsFrictionKind(kind) || kind == EffectKind::kArmature;
}

// Column of a per-joint effect at unit parameter `unit` (theta = neutral + e_unit).
Eigen::MatrixXd JointColumn(const PreparedData& prep, EffectKind kind, int j, int unit, double v_s) {
  std::vector<double> theta = Info(kind).neutral;
  if (kind == EffectKind::kStribeck) theta = {0.0, 0.0, v_s};
  theta[unit] = 1.0;
  const SmoothedData& sd = prep.sd;
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(prep.n, prep.rows);
  for (int r = 0; r < prep.rows; ++r) {
    const int k = prep.Sample(r);
    if (IsFrictionKind(kind)) {
      c(j, r) = sd.KernelAverage<double>(r, j, [&](double v) {
        return JointEffectTorque<double>(kind, theta.data(), 0.0, v, 0.0);
      });
    } else {
      c(j, r) = JointEffectTorque<double>(kind, theta.data(), sd.q(j, k), sd.qd(j, k), sd.qdd(j, k));
    }
  }
  return c;
}

// The system-wide column of payload, gain or delay.
Eigen::MatrixXd SystemColumn(const PreparedData& prep, EffectKind kind) {
  if (kind == EffectKind::kPayload) return prep.tip;
  if (kind == EffectKind::kGain) return prep.id_nominal;
  Eigen::MatrixXd c(prep.n, prep.rows);
  for (int r = 0; r < prep.rows; ++r) c.col(r) = prep.sd.dtau.col(prep.Sample(r));
  return c;
}

// True when the model under test already holds effect `kind` on `joint`.
bool InModel(const PreparedData& prep, EffectKind kind, int joint) {
  for (const Effect& e : prep.nominal->effects()) {
    if (e.kind == kind && e.joint == joint) return true;
  }
  return false;
}

// 95th percentile of |qd_j| (smoothed) over the train rows.
double SpeedP95(const PreparedData& prep, int j) {
  std::vector<double> v;
  for (int r : prep.train) v.push_back(std::abs(prep.sd.qd(j, prep.Sample(r))));
  const auto at = v.begin() + static_cast<std::ptrdiff_t>(0.95 * (v.size() - 1));
  std::nth_element(v.begin(), at, v.end());
  return *at;
}

// |cos| between two single-column candidates over the train rows.
double ColumnCosine(const PreparedData& prep, const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  double ab = 0, aa = 0, bb = 0;
  for (int r : prep.train) {
    ab += a.col(r).dot(b.col(r));
    aa += a.col(r).squaredNorm();
    bb += b.col(r).squaredNorm();
  }
  return aa > 0 && bb > 0 ? std::abs(ab) / std::sqrt(aa * bb) : 0.0;
}

// Reports every pair of (single-column) candidates the data cannot separate.
void ReportCollinear(const PreparedData& prep, CandidateLibrary* lib) {
  const auto& c = lib->candidates;
  for (std::size_t a = 0; a < c.size(); ++a) {
    for (std::size_t b = a + 1; b < c.size(); ++b) {
      if (c[a].columns.size() != 1 || c[b].columns.size() != 1) continue;
      if (c[a].joint != c[b].joint && c[a].joint > 0 && c[b].joint > 0) continue;
      const double cosine = ColumnCosine(prep, c[a].columns[0], c[b].columns[0]);
      if (cosine <= kCollinearCosine) continue;
      lib->not_identifiable.push_back(
          {c[b].kind, c[b].joint,
           StrCat("cannot be separated from ", c[a].label, " (|cos| = ", cosine,
                  " between their regressors); either may be named")});
    }
  }
}

}  // namespace

std::string EffectLabel(const Effect& effect) {
  const std::string name = Info(effect.kind).name;
  return effect.joint > 0 ? StrCat(name, " j", effect.joint) : name;
}

CandidateLibrary BuildCandidates(const PreparedData& prep, const std::vector<EffectKind>& kinds,
                                 bool has_tau) {
  std::vector<EffectKind> wanted = kinds;
  if (wanted.empty()) {
    for (const auto& info : AllEffectKinds()) {
      if (info.kind != EffectKind::kResidual) wanted.push_back(info.kind);
    }
  }
  CandidateLibrary lib;
  std::vector<bool> moves(prep.n);
  for (int j = 0; j < prep.n; ++j) {
    const double p95 = SpeedP95(prep, j);
    const double floor = std::max(3.0 * prep.qd_noise_std[j], 1e-3);
    moves[j] = p95 > floor;
    if (moves[j]) continue;
    for (EffectKind kind : wanted) {
      if (!MovesWithVelocity(kind)) continue;
      lib.not_identifiable.push_back(
          {kind, j + 1, StrCat("joint ", j + 1, " does not move (95th percentile |qd| = ", p95,
                               ", below ", floor, ")")});
    }
  }
  lib.static_data = std::none_of(moves.begin(), moves.end(), [](bool m) { return m; });
  for (const auto& info : AllEffectKinds()) {
    const EffectKind kind = info.kind;
    if (std::find(wanted.begin(), wanted.end(), kind) == wanted.end()) continue;
    if (kind == EffectKind::kResidual) continue;
    if (!info.per_joint) {
      if ((kind == EffectKind::kGain || kind == EffectKind::kDelay) && !has_tau) continue;
      if (InModel(prep, kind, 0)) continue;
      if (kind == EffectKind::kDelay && lib.static_data) {
        lib.not_identifiable.push_back({kind, 0, "static data: the torque does not change"});
        continue;
      }
      lib.candidates.push_back({kind, 0, 0.0, {SystemColumn(prep, kind)}, info.name});
      ++lib.distinct;
      continue;
    }
    for (int j = 0; j < prep.n; ++j) {
      if (MovesWithVelocity(kind) && !moves[j]) continue;
      if (InModel(prep, kind, j + 1)) continue;
      const std::string label = StrCat(info.name, " j", j + 1);
      ++lib.distinct;
      if (kind == EffectKind::kStribeck) {
        for (double v_s : kStribeckGrid) {
          lib.candidates.push_back({kind, j + 1, v_s,
                                    {JointColumn(prep, kind, j, 0, v_s), JointColumn(prep, kind, j, 1, v_s)},
                                    label});
        }
      } else {
        lib.candidates.push_back({kind, j + 1, 0.0, {JointColumn(prep, kind, j, 0, 0.0)}, label});
      }
    }
  }
  ReportCollinear(prep, &lib);
  return lib;
}

Effect EffectFromCoefficients(const Candidate& c, const Eigen::VectorXd& beta,
                              const Eigen::MatrixXd& cov) {
  DIFFDYN_CHECK(beta.size() == static_cast<int>(c.columns.size()), "EffectFromCoefficients: ",
                c.columns.size(), " coefficients expected, got ", beta.size());
  Effect e;
  e.kind = c.kind;
  e.joint = c.joint;
  const Eigen::VectorXd se = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  switch (c.kind) {
    case EffectKind::kStribeck:
      e.params = {beta[0], beta[1], c.v_s};
      e.stderrs = {se[0], se[1], 0.0};
      break;
    case EffectKind::kGain:  // beta = 1/k - 1
      e.params = {1.0 / (1.0 + beta[0])};
      e.stderrs = {se[0] / ((1.0 + beta[0]) * (1.0 + beta[0]))};
      break;
    default:
      e.params = {beta[0]};
      e.stderrs = {se[0]};
  }
  return e;
}

}  // namespace diffdyn
