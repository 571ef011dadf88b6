"""A dynamics model from numpy: predict a batch, take its exact Jacobian, roll it out.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/predict_and_jacobian.py [MODEL] [--quick]

MODEL is any model diffdyn loads (a model file `diffdyn train` or `diffdyn diagnose`
wrote, or an analytic name); the default is the analytic pendulum at 20 ms. The
Jacobian [dF/dx, dF/du] at the upright position is the linearisation a controller
(LQR, iLQR) starts from: its unstable eigenvalue says the pendulum falls.
"""

import sys

import numpy as np

import diffdyn

args = [a for a in sys.argv[1:] if a != "--quick"]
samples = 1000 if "--quick" in sys.argv else 100000
model = diffdyn.load_model(args[0] if args else "pendulum", dt=0.02)
n, m = model.state_size, model.action_size
print(model)

# A batch: one sample per row, (N, n) states and (N, m) actions.
rng = np.random.default_rng(0)
x = rng.uniform(-1.0, 1.0, (samples, n))
u = rng.uniform(-0.5, 0.5, (samples, m))
x_next = model.predict(x, u)
print(f"predicted {samples} transitions; mean |x' - x| = {np.abs(x_next - x).mean():.4g}")

# The exact Jacobian of one transition, here at the pendulum's upright position.
upright = np.zeros(n)
upright[0] = np.pi
jac = model.jacobian(upright, np.zeros(m))  # (n, n + m) = [dF/dx, dF/du]
a, b = jac[:, :n], jac[:, n:]
print("dF/dx =\n", np.array2string(a, precision=5))
print("dF/du =\n", np.array2string(b, precision=5))
print("|eigenvalues of dF/dx| =", np.array2string(np.abs(np.linalg.eigvals(a)), precision=5),
      "(> 1: unstable)")

# Batched Jacobians agree with central differences of predict.
jacs = model.jacobian(x[:8], u[:8])  # (8, n, n + m)
eps = 1e-6
fd = (model.predict(x[:8], u[:8] + eps) - model.predict(x[:8], u[:8] - eps)) / (2 * eps)
print(f"max |dF/du - central difference| over 8 samples: {np.abs(jacs[:, :, n] - fd).max():.2e}")

# A rollout of 50 steps (1 s) from rest slightly off upright, no torque.
start = upright.copy()
start[0] -= 0.01
states = model.rollout(start, np.zeros((50, m)))  # (51, n)
print(f"after 1 s without torque the angle is {states[-1, 0]:.3f} rad (started at {start[0]:.3f})")
