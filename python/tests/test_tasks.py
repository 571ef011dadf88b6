"""diffdyn.Task and diffdyn.ground_truth against the command line: the starts
`diffdyn control` runs from, the components `diffdyn collect` records, and the
equation of motion the components must add up to."""

import csv

import numpy as np
import pytest

import diffdyn
from conftest import run_cli


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_starts_are_the_command_lines(tmp_path):
    run_cli("control", "--system", "pendulum", "--controller", "lqr", "--starts", "4", "--seed", "5",
            "--quiet", "--out", str(tmp_path))
    rows = read_csv(tmp_path / "starts.csv")
    expected = np.array([[float(r["x0_1"]), float(r["x0_2"])] for r in rows])
    task = diffdyn.Task("pendulum")
    assert np.array_equal(task.sample_starts(4, seed=5), expected)
    assert not np.array_equal(task.sample_starts(4, seed=6), expected)


def test_task_cost_and_success_test():
    task = diffdyn.Task("pendulum")
    assert (task.state_size, task.action_size) == (2, 1)
    assert task.period == pytest.approx(0.008) and task.bound[0] == pytest.approx(2.5)
    assert task.running_cost(task.goal, [0.0]) == 0.0
    hanging = np.array([0.0, 0.0])
    assert task.running_cost(hanging, [0.0]) == pytest.approx(np.pi ** 2)  # w = 1, e = pi sin(pi / 2)
    # The action cost grows with |u| and is clipped at the bound.
    costs = task.running_cost(np.tile(task.goal, (3, 1)), [[0.5], [2.5], [9.0]])
    assert 0 < costs[0] < costs[1] == costs[2]
    assert task.succeeded([[np.pi, 0.0], [np.pi + 0.2, 0.0], [-np.pi, 0.1]]) == [True, False, True]


def test_plant_is_the_control_period_model():
    task = diffdyn.Task("cartpole")
    plant = task.plant()
    assert plant.time_step == pytest.approx(task.period)
    x = task.sample_starts(1, seed=2)
    longer = task.plant(dt=4 * task.period, substeps=16).predict(x, [[1.0]])
    four = x
    for _ in range(4):
        four = plant.predict(four, [[1.0]])
    np.testing.assert_allclose(longer, four, rtol=1e-12, atol=1e-12)


def test_ground_truth_is_what_collect_records(tmp_path):
    data = str(tmp_path / "arm.csv")
    run_cli("collect", "--system", "arm2", "--trajectories", "1", "--seconds", "0.4", "--seed", "2", "--quiet",
            "--out", data)
    rows = read_csv(data)
    column = lambda name: np.array([float(r[name]) for r in rows])
    states = np.stack([column(c) for c in ("q1", "q2", "qd1", "qd2")], axis=1)
    actions = np.stack([column("tau1"), column("tau2")], axis=1)[:-1]
    parts = diffdyn.ground_truth("arm2", states, actions)
    # The last sample holds the last action; collect records the torque drawn there.
    for name in ("m", "c", "g", "f"):
        expected = np.stack([column(f"{name}1"), column(f"{name}2")], axis=1)
        np.testing.assert_allclose(parts[name][:-1], expected[:-1], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(parts["kinetic"][:, 0], column("kinetic"), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(parts["potential"][:, 0], column("potential"), rtol=1e-9, atol=1e-9)
    # The components add up to the applied torque: H qdd + C qd + g + f = tau.
    total = parts["m"] + parts["c"] + parts["g"] + parts["f"]
    np.testing.assert_allclose(total, parts["tau"], rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match="ground_truth: expected states"):
        diffdyn.ground_truth("arm2", states, actions[:-1])
    with pytest.raises(ValueError, match="--system"):
        diffdyn.ground_truth("no-such-system", states, actions)
