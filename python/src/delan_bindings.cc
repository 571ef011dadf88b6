// diffdyn.delan_decompose: a DeLaN model file's torque split into the parts of the
// Euler-Lagrange equation (models/delan.h), with the same keys as
// diffdyn.ground_truth, so the learned parts line up with the true ones:
//
//   parts = diffdyn.delan_decompose("delan.json", q, qd, qdd)     # (N, n) each
//   truth = diffdyn.ground_truth("arm2", states, actions)
//   error = parts["g"] - truth["g"]
#include <string>

#include "arrays.h"
#include "bindings.h"
#include "diffdyn/models/delan.h"

namespace diffdyn::python {
namespace {

py::dict Decompose(const std::string& path, const py::handle& q_in, const py::handle& qd_in,
                   const py::handle& qdd_in, int threads) {
  const Delan model = LoadDelan(path);
  const int n = model.dof();
  const Batch q = ReadBatch(q_in, n, "delan_decompose: q");
  const Batch qd = ReadBatch(qd_in, n, "delan_decompose: qd");
  const Batch qdd = ReadBatch(qdd_in, n, "delan_decompose: qdd");
  DIFFDYN_CHECK(!q.single && qd.samples == q.samples && qdd.samples == q.samples,
                "delan_decompose: expected q, qd and qdd of shape (N, ", n, ") each, got ", q.samples, ", ",
                qd.samples, " and ", qdd.samples, " samples");
  DIFFDYN_CHECK(threads >= 0, "threads must be >= 0, got ", threads);
  DelanParts parts;
  {
    py::gil_scoped_release release;
    DelanWorkspace ws;
    parts = model.Decompose(q.matrix(), qd.matrix(), qdd.matrix(), &ws, threads);
  }
  py::dict out;
  out["tau"] = FromColumns(parts.torque);
  out["m"] = FromColumns(parts.inertial);
  out["c"] = FromColumns(parts.coriolis);
  out["g"] = FromColumns(parts.gravity);
  out["f"] = FromColumns(parts.friction);
  out["kinetic"] = FromColumns(parts.kinetic);
  out["potential"] = FromColumns(parts.potential);
  out["power"] = FromColumns(parts.power);
  out["min_mass_eigenvalue"] = FromColumns(parts.min_mass_eigenvalue);
  return out;
}

}  // namespace

void BindDelan(py::module_& m) {
  m.def("delan_decompose", &Decompose, py::arg("path"), py::arg("q"), py::arg("qd"), py::arg("qdd"),
        py::arg("threads") = 0,
        R"doc(The torque of the DeLaN model file `path` (kind delan or delan-friction) split into the
Euler-Lagrange equation's parts at q, qd, qdd (N, n each): a dict of (N, n) arrays
tau = m + c + g + f, m = H(q) qdd, c = C(q, qd) qd, g = dV/dq, f (the friction head; zeros
without one), and (N, 1) arrays kinetic, potential (V up to a constant), power (dE/dt,
friction excluded) and min_mass_eigenvalue (of H). Keys as diffdyn.ground_truth's.)doc");
}

}  // namespace diffdyn::python
