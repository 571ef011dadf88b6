"""A NeuralODE learned from numpy arrays, and its Jacobian against the true one.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/train_from_numpy.py [--quick]

The measurements here come from the analytic pendulum (diffdyn.load_model("pendulum")
rolled out under random torques); in practice they are your robot's log. Arrays
become a joint-space CSV (columns t, q1, qd1, tau1 and a trajectory number, the
format `diffdyn collect` writes), diffdyn.train fits an absolute NeuralODE to it,
diffdyn.evaluate scores it, and the learned model's exact Jacobian at the hanging
position is compared with the pendulum's own.
"""

import os
import shutil
import sys
import tempfile

import numpy as np

import diffdyn

quick = "--quick" in sys.argv
dt, steps, trajectories = 0.04, 50, 20 if quick else 100
truth = diffdyn.load_model("pendulum", dt=dt)

# Measurements as arrays: random starts, torques held for one sample each.
rng = np.random.default_rng(1)
starts = np.column_stack([rng.uniform(-np.pi, np.pi, trajectories), rng.uniform(-2, 2, trajectories)])
torques = rng.uniform(-1.0, 1.0, (trajectories, steps, 1))
states = truth.rollout(starts, torques)  # (trajectories, steps + 1, 2)

# The arrays as a joint-space CSV (the last sample of each trajectory has no torque of its own).
rows = []
for k in range(trajectories):
    tau = np.append(torques[k, :, 0], 0.0)
    for i in range(steps + 1):
        rows.append([k, i * dt, states[k, i, 0], states[k, i, 1], tau[i]])
folder = tempfile.mkdtemp(prefix="diffdyn-example-")
data = os.path.join(folder, "pendulum.csv")
np.savetxt(data, np.array(rows), delimiter=",", header="trajectory,t,q1,qd1,tau1", comments="", fmt="%.17g")

# Train and score: the dictionaries `diffdyn train --json` and `diffdyn eval --json` print.
path = os.path.join(folder, "abs-node.json")
summary = diffdyn.train(data, "abs-node", out=path, epochs=30 if quick else 200, hidden=64, seed=0)
print(f"trained {summary['parameters']} parameters on {summary['n_train']} transitions: "
      f"validation loss {summary['final_val_loss']:.3g}, {summary['seconds_per_epoch'] * 1e3:.1f} ms per epoch")
scores = diffdyn.evaluate(path, data)
print(f"single-step loss {scores['single_step_loss']:.3g} "
      f"(the 'state stays' baseline: {scores['baseline_single_step_loss']:.3g})")

# The learned model's Jacobian at rest, hanging, against the pendulum's.
learned = diffdyn.load_model(path)
rest, zero = np.zeros(2), np.zeros(1)
print("learned [dF/dx, dF/du] =\n", np.array2string(learned.jacobian(rest, zero), precision=4))
print("true    [dF/dx, dF/du] =\n", np.array2string(truth.jacobian(rest, zero), precision=4))
shutil.rmtree(folder)
