"""diffdyn.diagnose against `diffdyn diagnose --json`: the same summary from the
same computation, the files and plots it writes, and bad input as ValueError with
nothing written."""

import os

import numpy as np
import pytest

import diffdyn
from conftest import cli_json, run_cli

# Keys whose values differ between two runs of the same diagnosis.
RUN_DEPENDENT = {"seconds", "report", "extended_model"}


@pytest.fixture(scope="module")
def friction_log(tmp_path_factory):
    """A pendulum log with hidden viscous friction 0.2 N m s on joint 1."""
    path = str(tmp_path_factory.mktemp("diagnose") / "pendulum.csv")
    run_cli("collect", "--system", "pendulum", "--effect", "viscous:1=0.2", "--trajectories", "20", "--seed", "5",
            "--quiet", "--out", path)
    return path


def test_diagnose_returns_what_the_command_line_prints(friction_log, tmp_path):
    cli_out, py_out = str(tmp_path / "cli"), str(tmp_path / "py")
    expected = cli_json("diagnose", "--model", "pendulum", "--measured", friction_log, "--seed", "3", "--out", cli_out)
    found = diffdyn.diagnose("pendulum", friction_log, out=py_out, seed=3)
    assert set(found) == set(expected)
    for key in set(expected) - RUN_DEPENDENT:
        assert found[key] == expected[key], key
    viscous = [e for e in found["named_effects"] if e["kind"] == "viscous" and e["joint"] == 1]
    assert viscous and abs(viscous[0]["value"] - 0.2) < 0.03, found["named_effects"]
    for name in ("report.md", "extended_model.json", "residuals.csv", "residual_vs_velocity.png"):
        assert os.path.getsize(os.path.join(py_out, name)) > 0, name
    # The extended model is a model like any other, the command line's to the last bit.
    extended = diffdyn.load_model(found["extended_model"], dt=0.04)
    x, u = np.array([[0.3, 2.0], [-1.0, 0.5]]), np.array([[0.0], [1.0]])
    same = diffdyn.load_model(expected["extended_model"], dt=0.04).predict(x, u)
    assert extended.predict(x, u).tobytes() == same.tobytes()
    assert np.abs(extended.predict(x, u) - diffdyn.load_model("pendulum", dt=0.04).predict(x, u)).max() > 1e-3


def test_bad_input_raises_and_writes_nothing(friction_log, tmp_path):
    out = str(tmp_path / "never")
    with pytest.raises(ValueError, match="--alpha must be in"):
        diffdyn.diagnose("pendulum", friction_log, out=out, alpha=0.9)
    with pytest.raises(ValueError, match="--model"):
        diffdyn.diagnose("robot", friction_log, out=out)
    with pytest.raises(ValueError, match="has 1 joints but --model arm2 has 2"):
        diffdyn.diagnose("arm2", friction_log, out=out)
    assert not os.path.exists(out)
