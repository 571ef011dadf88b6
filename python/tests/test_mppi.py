"""diffdyn.Mppi: the built-in task cost against the same cost written in Python,
the same commands at any thread count, a swing-up on the task's plant, and a
Python cost's errors reaching the caller."""

import numpy as np
import pytest

import diffdyn

TASK = diffdyn.Task("pendulum")
DT, HORIZON, TERMINAL = 0.04, 25, 10.0
OPTIONS = dict(samples=400, horizon=HORIZON, lambda_=0.1, noise_variance=(0.5 * 2.5) ** 2)


def planning_model():
    return TASK.plant(dt=DT, substeps=1)


def task_cost_in_python(t, x, u, x_next):
    """TaskCost("pendulum", dt=DT) in numpy: dt c(x', u), plus the terminal state cost."""
    cost = DT * TASK.running_cost(x_next, u)
    if t == HORIZON - 1:
        cost += TERMINAL * TASK.running_cost(x_next, np.zeros_like(u))
    return cost


def commands(mppi, x, count=4):
    out = []
    for _ in range(count):
        u = mppi.command(x)
        out.append(u)
        x = planning_model().predict(x, u)
    return np.array(out)


def test_python_cost_gives_the_built_in_costs_commands():
    x = TASK.sample_starts(1, seed=3)[0]
    built_in = diffdyn.Mppi(planning_model(), diffdyn.TaskCost("pendulum", terminal_seconds=TERMINAL), seed=2,
                            **OPTIONS)
    python = diffdyn.Mppi(planning_model(), task_cost_in_python, u_min=-TASK.bound, u_max=TASK.bound, seed=2,
                          **OPTIONS)
    a, b = commands(built_in, x), commands(python, x)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(built_in.sample_costs, python.sample_costs, rtol=1e-9)
    assert np.abs(a).max() <= TASK.bound[0]
    assert built_in.nominal.shape == (HORIZON, 1)
    assert built_in.predict_nominal(x).shape == (HORIZON + 1, 2)


def test_same_commands_at_any_thread_count():
    x = TASK.sample_starts(1, seed=4)[0]
    one = diffdyn.Mppi(planning_model(), diffdyn.TaskCost("pendulum"), threads=1, seed=9, **OPTIONS)
    two = diffdyn.Mppi(planning_model(), diffdyn.TaskCost("pendulum"), threads=2, seed=9, **OPTIONS)
    assert commands(one, x).tobytes() == commands(two, x).tobytes()
    other = diffdyn.Mppi(planning_model(), diffdyn.TaskCost("pendulum"), threads=2, seed=10, **OPTIONS)
    assert not np.array_equal(commands(other, x), commands(two, x))


def test_swings_the_pendulum_up_on_the_plant():
    plant, hold = TASK.plant(), round(DT / TASK.period)
    successes = 0
    for x in TASK.sample_starts(3, seed=1):
        mppi = diffdyn.Mppi(planning_model(), diffdyn.TaskCost("pendulum"), seed=1, **{**OPTIONS, "samples": 1000})
        for _ in range(round(TASK.duration / DT)):
            u = mppi.command(x)
            for _ in range(hold):
                x = plant.predict(x, u)
        successes += TASK.succeeded(x)
    assert successes >= 2, f"{successes} of 3 swing-ups"


def test_python_cost_errors_reach_the_caller():
    x = TASK.goal

    def raises(t, x, u, x_next):
        raise KeyError("from the cost")

    with pytest.raises(KeyError, match="from the cost"):
        diffdyn.Mppi(planning_model(), raises, **OPTIONS).command(x)
    wrong_shape = diffdyn.Mppi(planning_model(), lambda t, x, u, xn: np.zeros(3), **OPTIONS)
    with pytest.raises(ValueError, match="one number per sample"):
        wrong_shape.command(x)
    not_finite = diffdyn.Mppi(planning_model(), lambda t, x, u, xn: np.full(len(x), np.inf), **OPTIONS)
    with pytest.raises(ValueError, match="non-finite"):
        not_finite.command(x)
    with pytest.raises(ValueError, match="TaskCost or a callable"):
        diffdyn.Mppi(planning_model(), "pendulum")
    with pytest.raises(ValueError, match="the cartpole task"):
        diffdyn.Mppi(planning_model(), diffdyn.TaskCost("cartpole"))
    with pytest.raises(ValueError, match="u_min needs 1 entries"):
        diffdyn.Mppi(planning_model(), raises, u_min=[1.0, 2.0])
