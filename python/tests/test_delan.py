"""diffdyn.delan_decompose: the parts add up to the torque, the torque error is the
one `diffdyn eval` reports for the same model and data, and the keys line up with
diffdyn.ground_truth's."""

import csv

import numpy as np
import pytest

import diffdyn
from conftest import cli_json, run_cli


@pytest.fixture(scope="module")
def arm_files(tmp_path_factory):
    """(data, model): a 2-link arm log with ground truth, a DeLaN with friction trained 3 epochs on it."""
    folder = tmp_path_factory.mktemp("delan")
    data, model = str(folder / "arm.csv"), str(folder / "delan.json")
    run_cli("collect", "--system", "arm2", "--trajectories", "4", "--seconds", "2", "--seed", "1", "--quiet",
            "--out", data)
    run_cli("train", "--data", data, "--model", "delan-friction", "--epochs", "3", "--hidden", "16", "--seed", "2",
            "--quiet", "--out", model)
    return data, model


def columns(path, names):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return np.array([[float(r[name]) for name in names] for r in rows])


def test_parts_add_up_and_match_eval(arm_files):
    data, model = arm_files
    q, qd, qdd = (columns(data, [f"{s}1", f"{s}2"]) for s in ("q", "qd", "qdd"))
    parts = diffdyn.delan_decompose(model, q, qd, qdd)
    assert parts["tau"].shape == q.shape and parts["kinetic"].shape == (len(q), 1)
    total = parts["m"] + parts["c"] + parts["g"] + parts["f"]
    np.testing.assert_allclose(total, parts["tau"], rtol=1e-10, atol=1e-10)
    assert (parts["min_mass_eigenvalue"] > 0).all()  # H = L L^T + eps I
    assert np.abs(parts["f"]).max() > 0  # the friction head
    tau = columns(data, ["tau1", "tau2"])
    expected = cli_json("eval", "--model", model, "--data", data)
    mse = np.sum((parts["tau"] - tau) ** 2, axis=1).mean()
    assert mse == pytest.approx(expected["torque_mse"], rel=1e-9)
    truth = diffdyn.ground_truth("arm2", np.hstack([q, qd]), tau[:-1])
    assert set(truth) - {"qdd"} <= set(parts)
    gravity_mse = np.sum((parts["g"] - truth["g"]) ** 2, axis=1).mean()
    assert gravity_mse == pytest.approx(expected["gravity_mse"], rel=1e-6)


def test_bad_input_is_a_value_error(arm_files):
    _, model = arm_files
    with pytest.raises(ValueError, match="delan_decompose: q"):
        diffdyn.delan_decompose(model, np.zeros((5, 3)), np.zeros((5, 2)), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="expected q, qd and qdd"):
        diffdyn.delan_decompose(model, np.zeros((5, 2)), np.zeros((4, 2)), np.zeros((5, 2)))
    with pytest.raises(ValueError, match="arm.csv: not valid JSON"):
        diffdyn.delan_decompose(arm_files[0], np.zeros((5, 2)), np.zeros((5, 2)), np.zeros((5, 2)))
