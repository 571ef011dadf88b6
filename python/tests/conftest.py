"""Fixtures of the Python module's tests: the command line, and a small dataset and
learned model made with it (so the module is compared with the command line on the
same files)."""

import json
import os
import subprocess

import pytest


def run_cli(*args):
    """`diffdyn ARGS...` (the binary of $DIFFDYN); its stdout."""
    binary = os.environ.get("DIFFDYN")
    if not binary:
        pytest.skip("DIFFDYN (the diffdyn binary) is not set; run the tests through ctest")
    result = subprocess.run([binary, *args], capture_output=True, text=True, check=False)
    assert result.returncode == 0, f"diffdyn {' '.join(args)}: {result.stderr}"
    return result.stdout


@pytest.fixture(scope="session")
def pendulum_files(tmp_path_factory):
    """(data, model): 6 pendulum trajectories of 2 s, an abs-node trained 2 epochs on them."""
    folder = tmp_path_factory.mktemp("pendulum")
    data, model = str(folder / "pendulum.csv"), str(folder / "model.json")
    run_cli("collect", "--system", "pendulum", "--trajectories", "6", "--seconds", "2", "--seed", "3",
            "--quiet", "--out", data)
    run_cli("train", "--data", data, "--model", "abs-node", "--epochs", "2", "--hidden", "16",
            "--seed", "1", "--quiet", "--out", model)
    return data, model


def cli_json(*args):
    return json.loads(run_cli(*args, "--json"))
