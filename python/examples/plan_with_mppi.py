"""MPPI from Python: swing a pendulum up with the built-in task cost, then hold it
at an angle with a cost written in numpy.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/plan_with_mppi.py [--quick] [--model FILE]

The controller plans over 40-ms steps with the task's own model (or a model file
diffdyn wrote, e.g. the NeuralODE of train_from_numpy.py, with --model) and acts on
the task's plant every 40 ms (five 8-ms control periods, the action held). The
built-in diffdyn.TaskCost runs in C++ on all cores; a Python cost is called once
per horizon step and rollout chunk with the GIL held, so it costs more per command.
"""

import sys
import time

import numpy as np

import diffdyn

quick = "--quick" in sys.argv
task = diffdyn.Task("pendulum")
dt = 0.04
model = (diffdyn.load_model(sys.argv[sys.argv.index("--model") + 1]) if "--model" in sys.argv
         else task.plant(dt=dt, substeps=1))
plant, hold = task.plant(), round(dt / task.period)
options = dict(samples=1000, horizon=25, lambda_=0.1, noise_variance=(0.5 * task.bound[0]) ** 2)


def run(mppi, x, seconds):
    """x after `seconds` on the plant under MPPI; the largest |u| and ms per command."""
    largest, spent, commands = 0.0, 0.0, round(seconds / dt)
    for _ in range(commands):
        start = time.perf_counter()
        u = mppi.command(x)
        spent += time.perf_counter() - start
        largest = max(largest, float(np.abs(u).max()))
        for _ in range(hold):
            x = plant.predict(x, u)
    return x, largest, 1e3 * spent / commands


# 1. Swing-up with the task's cost: success is |theta - pi| < 0.1 and |qd| < 0.5 after 5 s.
starts = task.sample_starts(2 if quick else 10, seed=1)
wins = 0
for s, x0 in enumerate(starts):
    mppi = diffdyn.Mppi(model, diffdyn.TaskCost("pendulum", dt=dt), seed=s, **options)
    x, largest, ms = run(mppi, x0, task.duration)
    wins += task.succeeded(x)
    print(f"start {s}: theta0 {x0[0]:+.2f} -> theta {x[0]:+.3f}, qd {x[1]:+.3f}; max |u| {largest:.2f} N m, "
          f"{ms:.1f} ms per command")
print(f"swing-up: {wins} of {len(starts)} starts reach the top")

# 2. Hold the pendulum at 0.4 rad from hanging (gravity's torque there, 1.9 N m, is within
#    the 2.5 N m bound) with a cost written in numpy.
GOAL = 0.4


def held(t, x, u, x_next):
    """Cost of the step x -> x_next under u: (B, n), (B, m), (B, n) -> (B,)."""
    angle = np.sin(0.5 * (x_next[:, 0] - GOAL))  # 0 at the goal, periodic
    return 100.0 * angle ** 2 + 0.1 * x_next[:, 1] ** 2 + 0.01 * u[:, 0] ** 2


mppi = diffdyn.Mppi(model, held, u_min=-task.bound, u_max=task.bound, seed=0, **options)
x, largest, ms = run(mppi, np.array([0.0, 0.0]), 2.0 if quick else 4.0)
print(f"held: theta {x[0]:.3f} (goal {GOAL}), max |u| {largest:.2f} N m, {ms:.1f} ms per command "
      f"with the Python cost")
ok = abs(x[0] - GOAL) < 0.05 and (wins >= len(starts) - 1)
sys.exit(0 if ok else 1)
