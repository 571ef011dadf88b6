// Analytic rigid-body models: one interface for inverse and forward dynamics.
//
// A robot with n joints obeys the manipulator equation
//
//   tau = ID(q, qd, qdd; p) = M(q; p) qdd + c(q, qd; p) + g(q; p),
//
// with q, qd, qdd, tau in R^n and p the model's named physical parameters
// (masses, lengths, gravity). Inverse dynamics ID is the primitive: it is
// linear in qdd, so the mass matrix and the forward dynamics follow from it,
//
//   M(q) e_i = ID(q, 0, e_i) - ID(q, 0, 0)          (column i, n + 1 calls),
//   qdd = FD(q, qd, tau) = M(q)^{-1} (tau - ID(q, qd, 0)).
//
// Each concrete model (simple_models.h, panda_dynamics.h) is a struct with
// templated static functions, evaluated on `double` for values and on
// `ceres::Jet` for derivatives with respect to q, qd, qdd or p:
//
//   template <typename T, typename Q, typename Qd, typename Qdd, typename P>
//   static JointVector<T, kDof> InverseDynamics(const Q& q, const Qd& qd, const Qdd& qdd, const P& p);
//   (and TipLoad with the same signature)
//
// q, qd, qdd and p are any Eigen vectors of scalar T (dynamic or fixed size) and the
// torque comes back as a fixed-size vector, so that the forward dynamics of the
// planners' inner loop (AnalyticDynamics) runs without a heap allocation.
//
// TipLoad is the joint torque needed to carry a unit point mass at the end of
// the last link (the `payload` effect scales it by the mass: ID is linear in a
// point mass). AnalyticModel is the runtime interface over these structs
// (chosen by `--model`), offering `double` and `DiagJet` evaluations so the
// diagnosis pipeline and Ceres fits work for any of them:
//
//   auto model = MakeAnalyticModel("pendulum");          // model_registry.h
//   Eigen::VectorXd p = ParseParams(*model, {"m=2"});    // named, validated
//   Eigen::VectorXd tau = model->InverseDynamics(q, qd, qdd, p);
//   Eigen::VectorXd qdd2 = model->ForwardDynamics(q, qd, tau, p);   // == qdd
#pragma once

#include <ceres/jet.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/jacobian.h"  // VectorX<T>, MatrixX<T>
#include "diffdyn/autodiff_ode/spd_solve.h"
#include "diffdyn/models/continuous_model.h"
#include "diffdyn/models/json_io.h"
#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// A fixed-size vector of N joint quantities of scalar T (the models' torques).
template <typename T, int N>
using JointVector = Eigen::Matrix<T, N, 1>;

/// Number of derivative directions of the Jets used by diagnosis fits (at most
/// this many parameters are differentiated at once).
inline constexpr int kDiagJetSize = 8;
/// The Jet type of the runtime model interface: value + kDiagJetSize derivatives.
using DiagJet = ceres::Jet<double, kDiagJetSize>;

/// One named model parameter, as written in `--param name=value`.
struct ParamSpec {
  std::string name;       ///< e.g. "m", "l", "m_pole"
  double default_value;   ///< the model_conventions.md default
  std::string unit;       ///< SI unit, e.g. "kg"
  std::string meaning;    ///< one-line description for reports
};

/// Runtime interface of an analytic model: tau = ID(q, qd, qdd; p) on double or
/// DiagJet, plus the tip load of a unit point mass. Sizes: q, qd, qdd, tau: n =
/// dof(); p: param_specs().size().
class AnalyticModel {
 public:
  virtual ~AnalyticModel() = default;

  /// The `--model` name ("pendulum", "cartpole", "double-pendulum", "arm2", "panda").
  virtual std::string name() const = 0;
  /// n, the number of joints.
  virtual int dof() const = 0;
  /// The named parameters p with defaults and units.
  virtual const std::vector<ParamSpec>& param_specs() const = 0;
  /// True when joint j (0-based) is prismatic (units N, m instead of N m, rad).
  virtual bool prismatic(int joint) const = 0;

  /// tau = M(q) qdd + c(q, qd) + g(q) (n), double.
  virtual Eigen::VectorXd InverseDynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                          const Eigen::VectorXd& qdd,
                                          const Eigen::VectorXd& p) const = 0;
  /// The same on Jets (derivatives w.r.t. whatever the caller seeded).
  virtual VectorX<DiagJet> InverseDynamics(const VectorX<DiagJet>& q, const VectorX<DiagJet>& qd,
                                           const VectorX<DiagJet>& qdd,
                                           const VectorX<DiagJet>& p) const = 0;
  /// Joint torque (n) that a unit point mass (1 kg) at the end of the last link needs.
  virtual Eigen::VectorXd TipLoad(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                  const Eigen::VectorXd& qdd, const Eigen::VectorXd& p) const = 0;
  /// The same on Jets.
  virtual VectorX<DiagJet> TipLoad(const VectorX<DiagJet>& q, const VectorX<DiagJet>& qd,
                                   const VectorX<DiagJet>& qdd,
                                   const VectorX<DiagJet>& p) const = 0;

  /// dx/dt = f(x, u) of AnalyticDynamics (below) on Jets (derivatives w.r.t. whatever
  /// the caller seeded in x and u): parameters p, the `actuated` joints (0-based; empty:
  /// all, a = n), viscous `damping` (n entries or empty); x (2n), u (a). Throws
  /// diffdyn::Error for bad sizes.
  virtual VectorX<DiagJet> Dynamics(const Eigen::VectorXd& p, const std::vector<int>& actuated,
                                    const Eigen::VectorXd& damping, const VectorX<DiagJet>& x,
                                    const VectorX<DiagJet>& u) const = 0;

  /// The Jacobians A = df/dx (2n x 2n) and B = df/du (2n x a) of Dynamics at (x, u),
  /// by forward-mode Jets (kDiagJetSize inputs per pass).
  void Linearize(const Eigen::VectorXd& p, const std::vector<int>& actuated, const Eigen::VectorXd& damping,
                 const Eigen::VectorXd& x, const Eigen::VectorXd& u, Eigen::MatrixXd* a,
                 Eigen::MatrixXd* b) const {
    const int nx = static_cast<int>(x.size()), na = static_cast<int>(u.size());
    a->resize(nx, nx);
    b->resize(nx, na);
    // Inputs z = (x, u), kDiagJetSize of them seeded per pass.
    for (int first = 0; first < nx + na; first += kDiagJetSize) {
      VectorX<DiagJet> xj = x.cast<DiagJet>(), uj = u.cast<DiagJet>();
      for (int k = 0; k < kDiagJetSize && first + k < nx + na; ++k) {
        const int i = first + k;
        (i < nx ? xj[i] : uj[i - nx]).v[k] = 1.0;
      }
      const VectorX<DiagJet> dxdt = Dynamics(p, actuated, damping, xj, uj);
      for (int k = 0; k < kDiagJetSize && first + k < nx + na; ++k) {
        const int i = first + k;
        for (int r = 0; r < nx; ++r) (i < nx ? (*a)(r, i) : (*b)(r, i - nx)) = dxdt[r].v[k];
      }
    }
  }

  /// The model as a transition model of x = (q, qd) over options.dt
  /// (continuous_model.h): AnalyticDynamics (below) with parameters p, the `actuated`
  /// joints (0-based; empty: all) and viscous `damping` (n entries or empty), on
  /// `system` (2n states, one action per actuated joint). Batched on double without
  /// virtual calls per step. Throws diffdyn::Error for bad sizes or options.
  virtual std::unique_ptr<TransitionModel> MakeTransitionModel(const Eigen::VectorXd& p,
                                                               std::vector<int> actuated,
                                                               Eigen::VectorXd damping,
                                                               SystemDescription system,
                                                               const ContinuousOptions& options) const = 0;

  /// The default parameter vector p (size param_specs().size()).
  Eigen::VectorXd DefaultParams() const {
    const auto& specs = param_specs();
    Eigen::VectorXd p(static_cast<int>(specs.size()));
    for (int i = 0; i < p.size(); ++i) p[i] = specs[i].default_value;
    return p;
  }

  /// Index of parameter `name` in p, or -1.
  int ParamIndex(const std::string& name) const {
    const auto& specs = param_specs();
    for (int i = 0; i < static_cast<int>(specs.size()); ++i) {
      if (specs[i].name == name) return i;
    }
    return -1;
  }

  /// M(q) (n x n) from n + 1 inverse-dynamics calls: M e_i = ID(q,0,e_i) - ID(q,0,0).
  Eigen::MatrixXd MassMatrix(const Eigen::VectorXd& q, const Eigen::VectorXd& p) const {
    const int n = dof();
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
    const Eigen::VectorXd bias = InverseDynamics(q, zero, zero, p);
    Eigen::MatrixXd m(n, n);
    for (int i = 0; i < n; ++i) {
      m.col(i) = InverseDynamics(q, zero, Eigen::VectorXd::Unit(n, i), p) - bias;
    }
    return 0.5 * (m + m.transpose());
  }

  /// qdd = M(q)^{-1} (tau - ID(q, qd, 0)) (n). Throws NumericalError if M is singular.
  Eigen::VectorXd ForwardDynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                  const Eigen::VectorXd& tau, const Eigen::VectorXd& p) const {
    const Eigen::VectorXd bias = InverseDynamics(q, qd, Eigen::VectorXd::Zero(dof()), p);
    const Eigen::LLT<Eigen::MatrixXd> llt(MassMatrix(q, p));
    if (llt.info() != Eigen::Success) {
      throw NumericalError(StrCat(name(), ": mass matrix is not positive definite"));
    }
    return llt.solve(tau - bias);
  }

  /// Checks that q, qd, qdd (n each) and p have the right sizes; names `what` on failure.
  void CheckSizes(const Eigen::VectorXd& q, const Eigen::VectorXd& p, const std::string& what) const {
    DIFFDYN_CHECK(q.size() == dof(), what, ": model ", name(), " has ", dof(), " joints, got ",
                  q.size());
    DIFFDYN_CHECK(p.size() == static_cast<int>(param_specs().size()), what, ": model ", name(),
                  " has ", param_specs().size(), " parameters, got ", p.size());
  }
};

/// v (N) as a dynamic-size vector, copied entry by entry (g++ 12 takes Eigen's masked
/// AVX-512 load of a small fixed-size vector for an out-of-bounds read, -Warray-bounds).
template <typename T, int N>
VectorX<T> ToDynamic(const JointVector<T, N>& v) {
  VectorX<T> out(N);
  for (int i = 0; i < N; ++i) out[i] = v[i];
  return out;
}

/// AnalyticModel over a struct `Model` with static members kName, kDof, Specs(),
/// Prismatic(j), InverseDynamics<T>(q, qd, qdd, p) and TipLoad<T>(q, qd, qdd, p).
template <typename Model>
class AnalyticModelAdapter final : public AnalyticModel {
 public:
  AnalyticModelAdapter() : specs_(Model::Specs()) {}
  std::string name() const override { return Model::kName; }
  int dof() const override { return Model::kDof; }
  const std::vector<ParamSpec>& param_specs() const override { return specs_; }
  bool prismatic(int joint) const override { return Model::Prismatic(joint); }
  Eigen::VectorXd InverseDynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                  const Eigen::VectorXd& qdd,
                                  const Eigen::VectorXd& p) const override {
    return ToDynamic(Model::template InverseDynamics<double>(q, qd, qdd, p));
  }
  VectorX<DiagJet> InverseDynamics(const VectorX<DiagJet>& q, const VectorX<DiagJet>& qd,
                                   const VectorX<DiagJet>& qdd,
                                   const VectorX<DiagJet>& p) const override {
    return ToDynamic(Model::template InverseDynamics<DiagJet>(q, qd, qdd, p));
  }
  Eigen::VectorXd TipLoad(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                          const Eigen::VectorXd& qdd, const Eigen::VectorXd& p) const override {
    return ToDynamic(Model::template TipLoad<double>(q, qd, qdd, p));
  }
  VectorX<DiagJet> TipLoad(const VectorX<DiagJet>& q, const VectorX<DiagJet>& qd,
                           const VectorX<DiagJet>& qdd,
                           const VectorX<DiagJet>& p) const override {
    return ToDynamic(Model::template TipLoad<DiagJet>(q, qd, qdd, p));
  }

  VectorX<DiagJet> Dynamics(const Eigen::VectorXd& p, const std::vector<int>& actuated,
                            const Eigen::VectorXd& damping, const VectorX<DiagJet>& x,
                            const VectorX<DiagJet>& u) const override;

  std::unique_ptr<TransitionModel> MakeTransitionModel(const Eigen::VectorXd& p,
                                                       std::vector<int> actuated,
                                                       Eigen::VectorXd damping,
                                                       SystemDescription system,
                                                       const ContinuousOptions& options) const override;

 private:
  std::vector<ParamSpec> specs_;
};

/// The manipulator equation of a compile-time analytic model (a struct as in
/// simple_models.h) as continuous dynamics for ContinuousTransitionModel
/// (continuous_model.h), on any scalar: x = (q, qd) (2n), theta = p, u the torques of
/// the joints in `actuated` (a entries; empty: every joint, a = n),
///
///   dx/dt = (qd, M(q)^{-1} (B u - ID(q, qd, 0) - D qd)),   M(q) e_i = ID(q, qd, e_i) - ID(q, qd, 0),
///
/// B the n x a selection of the actuated joints, D = diag(damping) the viscous joint
/// friction (n entries; empty: none).
template <typename Model>
struct AnalyticDynamics {
  /// 0-based joints driven by u's entries, increasing; empty: all.
  std::vector<int> actuated{};
  /// Viscous friction coefficient of each joint (n), or empty.
  Eigen::VectorXd damping{};

  /// dx/dt (2n) at x (2n), u (a) and theta; fixed-size temporaries only (no heap
  /// allocation once dxdt has its size).
  template <typename T>
  void operator()(const VectorX<T>& x, const VectorX<T>& u, const VectorX<T>& theta, double,
                  VectorX<T>& dxdt) const {
    constexpr int n = Model::kDof;
    using Vector = JointVector<T, n>;
    const Vector q = x.template head<n>(), qd = x.template tail<n>();
    // n + 1 calls: the bias c + g, then the mass matrix's columns (ID is affine in qdd).
    const Vector bias = Model::template InverseDynamics<T>(q, qd, Vector::Zero().eval(), theta);
    Eigen::Matrix<T, n, n> mass;
    for (int i = 0; i < n; ++i) {
      mass.col(i) = Model::template InverseDynamics<T>(q, qd, Vector::Unit(i).eval(), theta) - bias;
    }
    Vector force = -bias;
    if (actuated.empty()) {
      force += u;
    } else {
      for (std::size_t k = 0; k < actuated.size(); ++k) force[actuated[k]] += u[static_cast<Eigen::Index>(k)];
    }
    for (Eigen::Index j = 0; j < damping.size(); ++j) force[j] -= damping[j] * qd[j];
    dxdt.resize(2 * n);
    dxdt.template head<n>() = qd;
    dxdt.template tail<n>() = SpdSolve(mass, force);  // mass.llt() would drop Jets whose value is 0
  }
};

template <typename Model>
VectorX<DiagJet> AnalyticModelAdapter<Model>::Dynamics(const Eigen::VectorXd& p, const std::vector<int>& actuated,
                                                       const Eigen::VectorXd& damping, const VectorX<DiagJet>& x,
                                                       const VectorX<DiagJet>& u) const {
  const int n = Model::kDof;
  const int na = actuated.empty() ? n : static_cast<int>(actuated.size());
  DIFFDYN_CHECK(x.size() == 2 * n && u.size() == na && p.size() == static_cast<Eigen::Index>(specs_.size()) &&
                    (damping.size() == 0 || damping.size() == n),
                Model::kName, ": Dynamics expects x of ", 2 * n, ", u of ", na, ", ", specs_.size(),
                " parameters and ", n, " damping coefficients, got ", x.size(), ", ", u.size(), ", ", p.size(),
                " and ", damping.size());
  VectorX<DiagJet> dxdt;
  AnalyticDynamics<Model>{actuated, damping}(x, u, p.cast<DiagJet>().eval(), 0.0, dxdt);
  return dxdt;
}

template <typename Model>
std::unique_ptr<TransitionModel> AnalyticModelAdapter<Model>::MakeTransitionModel(
    const Eigen::VectorXd& p, std::vector<int> actuated, Eigen::VectorXd damping,
    SystemDescription system, const ContinuousOptions& options) const {
  const int n = Model::kDof;
  DIFFDYN_CHECK(p.size() == static_cast<Eigen::Index>(specs_.size()), Model::kName, ": ", specs_.size(),
                " parameters expected, got ", p.size());
  DIFFDYN_CHECK(damping.size() == 0 || damping.size() == n, Model::kName, ": damping needs ", n,
                " entries, got ", damping.size());
  for (int j : actuated) DIFFDYN_CHECK(j >= 0 && j < n, Model::kName, ": no joint ", j + 1);
  const int a = actuated.empty() ? n : static_cast<int>(actuated.size());
  DIFFDYN_CHECK(system.state_size() == 2 * n && system.action_size() == a, Model::kName,
                ": the system must have ", 2 * n, " states and ", a, " actions");
  return std::make_unique<ContinuousTransitionModel<AnalyticDynamics<Model>>>(
      AnalyticDynamics<Model>{std::move(actuated), std::move(damping)}, std::move(system), p, options,
      Model::kName);
}

/// The state (q1..qn, qd1..qdn) and action (tau1..taun) of an analytic model with n
/// joints; revolute joints' q are angles, seen as sin/cos by learned models.
inline SystemDescription AnalyticSystem(const AnalyticModel& model) {
  SystemDescription s;
  s.name = model.name();
  const int n = model.dof();
  for (int j = 1; j <= n; ++j) s.state_names.push_back(StrCat("q", j));
  for (int j = 1; j <= n; ++j) s.state_names.push_back(StrCat("qd", j));
  for (int j = 1; j <= n; ++j) s.action_names.push_back(StrCat("tau", j));
  for (int j = 0; j < n; ++j) {
    if (!model.prismatic(j)) s.angles.push_back(j);
  }
  s.angle_features = AngleFeatures::kSinCos;
  return s;
}

/// Largest magnitude a physical parameter may be given (SI units).
inline constexpr double kMaxParamMagnitude = 1e6;

/// p from the defaults overridden by `assignments` ("name=value", as given to
/// --param; a 3-vector parameter `v` with entries v_x, v_y, v_z also accepts
/// "v=a,b,c"). Throws diffdyn::Error naming the option for an unknown name or a
/// value that is not a finite number of magnitude at most kMaxParamMagnitude.
inline Eigen::VectorXd ParseParams(const AnalyticModel& model,
                                   const std::vector<std::string>& assignments,
                                   Eigen::VectorXd p = Eigen::VectorXd()) {
  if (p.size() == 0) p = model.DefaultParams();
  auto parse_number = [&](const std::string& text, const std::string& option) {
    std::size_t used = 0;
    double value = 0;
    try {
      value = std::stod(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    DIFFDYN_CHECK(used == text.size() && !text.empty() && std::isfinite(value), "--param ",
                  option, ": '", text.substr(0, 40), "' is not a finite number");
    DIFFDYN_CHECK(std::abs(value) <= kMaxParamMagnitude, "--param ", option.substr(0, 60), ": ", value,
                  " is outside [-1e6, 1e6] (parameters are in SI units)");
    return value;
  };
  for (const std::string& assignment : assignments) {
    const auto eq = assignment.find('=');
    DIFFDYN_CHECK(eq != std::string::npos && eq > 0, "--param ", assignment,
                  ": expected name=value");
    const std::string name = assignment.substr(0, eq);
    const std::string value = assignment.substr(eq + 1);
    const int index = model.ParamIndex(name);
    if (index >= 0) {
      p[index] = parse_number(value, assignment);
      continue;
    }
    // A 3-vector parameter given as name=a,b,c.
    const int ix = model.ParamIndex(name + "_x");
    std::string known;
    for (const auto& spec : model.param_specs()) {
      if (!known.empty()) known += ", ";
      known += spec.name;
    }
    DIFFDYN_CHECK(ix >= 0, "--param ", assignment, ": model ", model.name(),
                  " has no parameter '", name, "' (it has: ", known, ")");
    std::vector<std::string> parts;
    std::size_t start = 0;
    for (std::size_t comma; (comma = value.find(',', start)) != std::string::npos;
         start = comma + 1) {
      parts.push_back(value.substr(start, comma - start));
    }
    parts.push_back(value.substr(start));
    DIFFDYN_CHECK(parts.size() == 3, "--param ", assignment, ": expected three values x,y,z");
    const char* axes[3] = {"_x", "_y", "_z"};
    for (int k = 0; k < 3; ++k) {
      const int i = model.ParamIndex(name + axes[k]);
      DIFFDYN_CHECK(i >= 0, "--param ", assignment, ": no parameter ", name, axes[k]);
      p[i] = parse_number(parts[k], assignment);
    }
  }
  return p;
}

/// p from `p` (default: the model's defaults) overridden by the JSON file at
/// `path`, an object {name: value} or {"params": {name: value}} with the names
/// and limits of ParseParams; a vector parameter is {name: [x, y, z]} or its
/// three components. Throws diffdyn::Error "<path>: ..." (one line).
inline Eigen::VectorXd ReadParamsFile(const AnalyticModel& model, const std::string& path,
                                      Eigen::VectorXd p = Eigen::VectorXd()) {
  nlohmann::json j = ReadJsonFile(path);
  if (j.is_object() && j.contains("params")) j = nlohmann::json(j["params"]);
  DIFFDYN_CHECK(j.is_object(), path, ": expected an object {name: value}");
  std::vector<std::string> assignments;
  for (const auto& [name, value] : j.items()) {
    // A vector parameter (name_x, name_y, name_z) may be given as [x, y, z].
    if (value.is_array() && value.size() == 3 && value[0].is_number() && value[1].is_number() &&
        value[2].is_number()) {
      assignments.push_back(StrCat(name, "=", value[0].get<double>(), ",", value[1].get<double>(), ",",
                                   value[2].get<double>()));
      continue;
    }
    DIFFDYN_CHECK(value.is_number(), path, ": '", name.substr(0, 40),
                  "' is not a number (or [x, y, z] for a vector parameter)");
    assignments.push_back(StrCat(name, "=", value.get<double>()));
  }
  try {
    return ParseParams(model, assignments, std::move(p));
  } catch (const Error& e) {
    throw Error(StrCat(path, ": ", e.what()));
  }
}

}  // namespace diffdyn
