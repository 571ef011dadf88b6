"""Precision from Python: diffdyn.train(precision=...), load_model(precision=...),
Model.precision and evaluate(precision=...) do what the commands' --precision does,
and float32 results follow float64 to float32's rounding, not to the bit."""

import numpy as np
import pytest

import diffdyn
from conftest import cli_json, run_cli


def test_float32_training_matches_the_command_line(pendulum_files, tmp_path):
    data, _ = pendulum_files
    cli_path, py_path = str(tmp_path / "cli.json"), str(tmp_path / "py.json")
    expected = cli_json("train", "--data", data, "--model", "abs-nn", "--epochs", "2", "--hidden", "12",
                        "--seed", "5", "--precision", "f32", "--quiet", "--out", cli_path)
    summary = diffdyn.train(data, "abs-nn", out=py_path, epochs=2, hidden=12, seed=5, precision="f32")
    assert summary["precision"] == "f32" and expected["precision"] == "f32"
    assert summary["final_val_loss"] == expected["final_val_loss"]
    single = diffdyn.load_model(py_path)
    assert single.precision == "f32"
    double = diffdyn.load_model(py_path, precision="f64")
    assert double.precision == "f64"
    rng = np.random.default_rng(3)
    x, u = rng.standard_normal((50, 2)), rng.standard_normal((50, 1))
    a, b = single.predict(x, u), double.predict(x, u)
    assert not np.array_equal(a, b)  # really computed in float
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)


def test_evaluate_converts_like_the_command_line(pendulum_files):
    data, model = pendulum_files
    expected = cli_json("eval", "--model", model, "--data", data, "--precision", "f32")
    assert diffdyn.evaluate(model, data, precision="f32") == expected
    f64 = diffdyn.evaluate(model, data)
    assert expected["single_step_loss"] == pytest.approx(f64["single_step_loss"], rel=1e-3)


def test_delan_trains_in_float32(tmp_path):
    data, path = str(tmp_path / "arm.csv"), str(tmp_path / "delan.json")
    run_cli("collect", "--system", "arm2", "--trajectories", "3", "--seconds", "2", "--seed", "4", "--quiet",
            "--out", data)
    summary = diffdyn.train(data, "delan", out=path, epochs=3, hidden=16, seed=1, precision="f32")
    assert summary["precision"] == "f32"
    scores = diffdyn.evaluate(path, data)
    assert scores["precision"] == "f32" and np.isfinite(scores["torque_mse"])
    assert diffdyn.evaluate(path, data, precision="f64")["torque_mse"] == pytest.approx(scores["torque_mse"],
                                                                                      rel=1e-3)


def test_bad_precision_is_a_value_error(pendulum_files, tmp_path):
    data, model = pendulum_files
    with pytest.raises(ValueError, match="precision"):
        diffdyn.load_model(model, precision="f16")
    with pytest.raises(ValueError, match="precision"):
        diffdyn.train(data, "abs-nn", out=str(tmp_path / "m.json"), precision="half")
    with pytest.raises(ValueError, match="precision"):
        diffdyn.load_model("pendulum", dt=0.01, precision="f32")  # analytic models compute in float64
