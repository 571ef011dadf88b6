"""diffdyn from Python: robot dynamics models over numpy batches.

    import numpy as np
    import diffdyn

    model = diffdyn.load_model("pendulum", dt=0.02)      # or a model file diffdyn wrote
    x = np.zeros((1000, model.state_size))              # one sample per row
    u = np.ones((1000, model.action_size))
    x_next = model.predict(x, u)                        # (1000, n)
    jac = model.jacobian(x, u)                          # (1000, n, n + m) = [dF/dx, dF/du]
    states = model.rollout(x[:5], np.ones((5, 50, 1)))  # (5, 51, n)
    summary = diffdyn.evaluate("model.json", "data.csv")  # the `diffdyn eval --json` dictionary

    task = diffdyn.Task("pendulum")                     # swing-up: cost, bounds, starts, plant
    mppi = diffdyn.Mppi(model, diffdyn.TaskCost("pendulum"), horizon=50, seed=1)
    u = mppi.command(task.sample_starts(1, seed=1)[0])  # (m,); a Python cost(t, x, u, x_next) works too
    found = diffdyn.diagnose("panda", "panda_log.csv", out="diag")  # `diffdyn diagnose --json`'s dictionary

Bad input raises ValueError with the command line's message; a numerical failure
(a prediction that overflows) raises RuntimeError. The native work runs with the
GIL released, on all cores unless `threads` says otherwise; results do not depend
on the thread count. `diffdyn.torch_function` makes a model callable from PyTorch.
"""

import os
import subprocess
import sys
import warnings

from . import _diffdyn
from ._diffdyn import (Model, Mppi, Task, TaskCost, __version__, delan_decompose, evaluate, ground_truth, load_model,
                       train)

__all__ = ["Model", "Mppi", "Task", "TaskCost", "delan_decompose", "diagnose", "evaluate", "ground_truth",
           "load_model", "train", "__version__"]


def diagnose(model, measured, out, plots=True, **options):
    """What the simulation `model` gets wrong on `measured` data: the dictionary
    `diffdyn diagnose --model MODEL --measured MEASURED --out OUT --json` prints.

    MODEL is an analytic model name (pendulum, cartpole, double-pendulum, arm2, panda)
    or an extended-physics file (a diagnosis fed back); MEASURED a joint-space CSV or
    a dataset folder. OUT receives report.md, extended_model.json (load it with
    diffdyn.load_model(path, dt=...)), residuals.csv and, with plots=True, the PNGs
    drawn from it. Keyword options are the command's in snake case: params (a list of
    "name=value"), params_file, fit_params, scale_params, cutoff_hz, holdout,
    phase_period, rollout_horizon, min_effect_to_noise, alpha, seed.
    """
    summary = _diffdyn._diagnose(model, measured, out, **options)
    if plots:
        script = os.path.join(_diffdyn._plots_dir(), "diagnose_residuals.py")
        args = [os.path.join(out, "residuals.csv"), out, str(len(summary["nominal_rmse"]))]
        done = subprocess.run([sys.executable, script, *args], env={**os.environ, "MPLBACKEND": "Agg"},
                              capture_output=True, text=True, check=False)
        if done.returncode != 0:
            warnings.warn(f"plot script {script} failed; the CSV data is written: {done.stderr.strip()[-300:]}")
    return summary
