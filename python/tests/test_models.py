"""diffdyn.Model and diffdyn.evaluate against the command line and the library's
own paths: shapes, zero-copy inputs, thread-count independence, Jacobians against
central differences, rollouts against repeated predictions, errors as exceptions
and the GIL released during native work."""

import os
import threading
import time

import numpy as np
import pytest

import diffdyn
from conftest import cli_json

rng = np.random.default_rng(7)


def pendulum(dt=0.02):
    return diffdyn.load_model("pendulum", dt=dt)


def batch(model, n, scale=1.0):
    return (scale * rng.standard_normal((n, model.state_size)),
            scale * rng.standard_normal((n, model.action_size)))


def test_module_describes_the_model():
    model = pendulum()
    assert diffdyn.__version__
    assert model.kind == "pendulum" and model.spec == "pendulum"
    assert (model.state_size, model.action_size) == (2, 1)
    assert model.time_step == pytest.approx(0.02)
    assert len(model.state_names) == 2 and len(model.action_names) == 1
    assert model.differentiable
    assert "pendulum" in repr(model)


def test_predict_is_per_sample_and_independent_of_threads():
    model = pendulum()
    x, u = batch(model, 600)  # more than two chunks of 256
    one = model.predict(x, u, threads=1)
    two = model.predict(x, u, threads=2)
    assert one.shape == (600, 2) and one.dtype == np.float64
    assert one.tobytes() == two.tobytes()
    for i in (0, 255, 256, 599):
        # One sample and a batch may take different kernels (rounding only).
        np.testing.assert_allclose(model.predict(x[i], u[i]), one[i], rtol=1e-12, atol=1e-12)
    # The pendulum swings under gravity: the state moved.
    assert np.abs(one - x).max() > 1e-3


def test_predict_over_given_intervals():
    model = pendulum(0.02)
    x, u = batch(model, 4)
    assert np.array_equal(model.predict(x, u, dt=0.02), model.predict(x, u))
    longer = model.predict(x, u, dt=np.full(4, 0.04))
    np.testing.assert_allclose(longer, pendulum(0.04).predict(x, u), rtol=0, atol=1e-12)
    assert np.abs(longer - model.predict(x, u)).max() > 1e-3
    with pytest.raises(ValueError, match="positive interval"):
        model.predict(x, u, dt=np.zeros(4))


def test_inputs_are_read_in_place_where_the_layout_allows():
    model = pendulum()
    x, u = batch(model, 50)
    before = diffdyn._diffdyn._input_copies()
    reference = model.predict(x, u)
    assert diffdyn._diffdyn._input_copies() == before  # C-contiguous float64: views
    fortran = np.asfortranarray(x)
    assert np.array_equal(model.predict(fortran, u), reference)
    assert diffdyn._diffdyn._input_copies() == before + 1  # converted once
    single = model.predict(x.astype(np.float32), u.astype(np.float32))
    assert single.dtype == np.float32
    np.testing.assert_allclose(single, reference, rtol=1e-5, atol=1e-5)


def test_jacobian_matches_central_differences():
    for model in (pendulum(), diffdyn.load_model("cartpole", dt=0.05)):
        x, u = batch(model, 4, 0.5)
        jac = model.jacobian(x, u)
        n, m = model.state_size, model.action_size
        assert jac.shape == (4, n, n + m)
        z = np.hstack([x, u])
        eps = 1e-6
        for k in range(n + m):
            zp, zm = z.copy(), z.copy()
            zp[:, k] += eps
            zm[:, k] -= eps
            fd = (model.predict(zp[:, :n], zp[:, n:]) - model.predict(zm[:, :n], zm[:, n:])) / (2 * eps)
            np.testing.assert_allclose(jac[:, :, k], fd, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(model.jacobian(x[1], u[1]), jac[1], rtol=1e-12, atol=1e-12)


def test_learned_model_jacobian_and_rollout(pendulum_files):
    _, path = pendulum_files
    model = diffdyn.load_model(path)
    assert model.kind == "abs-node"
    x, u = batch(model, 3, 0.5)
    jac = model.jacobian(x, u)
    eps = 1e-6
    fd = (model.predict(x, u + eps) - model.predict(x, u - eps)) / (2 * eps)
    np.testing.assert_allclose(jac[:, :, 2], fd, rtol=1e-5, atol=1e-7)
    actions = rng.standard_normal((3, 5, 1))
    states = model.rollout(x, actions)
    assert states.shape == (3, 6, 2)
    step = x
    for t in range(5):
        step = model.predict(step, actions[:, t])
        np.testing.assert_allclose(states[:, t + 1], step, rtol=1e-12, atol=1e-12)
    # One sample and a batch may take different kernels (rounding only).
    np.testing.assert_allclose(model.rollout(x[0], actions[0]), states[0], rtol=1e-12, atol=1e-12)


def test_evaluate_returns_what_the_command_line_prints(pendulum_files):
    data, path = pendulum_files
    expected = cli_json("eval", "--model", path, "--data", data)
    assert diffdyn.evaluate(path, data) == expected
    assert diffdyn.evaluate(diffdyn.load_model(path), data, threads=1) == expected
    physics = cli_json("eval", "--model", "pendulum", "--data", data, "--substeps", "2")
    assert diffdyn.evaluate("pendulum", data, substeps=2) == physics
    assert physics["single_step_loss"] < expected["baseline_single_step_loss"]


def test_errors_are_python_exceptions_with_the_command_lines_messages(tmp_path):
    model = pendulum()
    x, u = batch(model, 3)
    with pytest.raises(ValueError, match=r"predict: x: expected shape \(2,\) or \(N, 2\)"):
        model.predict(np.zeros((3, 3)), u)
    with pytest.raises(ValueError, match="3 samples, u has 2"):
        model.predict(x, u[:2])
    bad = x.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        model.predict(bad, u)
    with pytest.raises(ValueError, match="expected numbers"):
        model.predict(np.array([["a", "b"]]), u[:1])
    with pytest.raises(ValueError, match="--model"):
        diffdyn.load_model(str(tmp_path / "missing.json"))
    with pytest.raises(ValueError, match="dt"):
        diffdyn.load_model("pendulum")
    with pytest.raises(ValueError, match="solver"):
        diffdyn.load_model("pendulum", dt=0.1, solver="rk5")
    oracle = diffdyn.load_model("oracle")
    assert not oracle.differentiable
    with pytest.raises(ValueError, match="no derivatives"):
        oracle.jacobian(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="--data"):
        diffdyn.evaluate("pendulum", str(tmp_path / "missing.csv"))
    with pytest.raises(ValueError, match="rollout: actions"):
        model.rollout(x, np.zeros((3, 4, 2)))
    with pytest.raises(RuntimeError, match="finite"):
        model.predict(np.array([1e308, 1e308]), np.array([1e308]))


def test_native_work_releases_the_gil():
    model = diffdyn.load_model("panda", dt=0.004)
    x, u = batch(model, 200, 0.1)
    span = []

    def work():
        start = time.perf_counter()
        model.jacobian(x, u, threads=1)
        span.extend([start, time.perf_counter()])

    worker = threading.Thread(target=work)
    ticks = []
    worker.start()
    while worker.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.0005)
    worker.join()
    start, end = span
    inside = sum(start < t < end for t in ticks)
    # Had the call held the GIL, this thread could not have run between the
    # worker's two clock readings.
    assert end - start > 0.02, "the call is too short to tell"
    assert inside >= 5, f"{inside} ticks during a {end - start:.3f} s native call"


def test_train_returns_what_the_command_line_prints(pendulum_files, tmp_path):
    data, _ = pendulum_files
    options = ["--model", "res-node", "--epochs", "2", "--hidden", "12", "--seed", "4", "--loss", "multi"]
    cli_path, py_path = str(tmp_path / "cli.json"), str(tmp_path / "py.json")
    expected = cli_json("train", "--data", data, *options, "--quiet", "--out", cli_path)
    summary = diffdyn.train(data, "res-node", out=py_path, epochs=2, hidden=12, seed=4, loss="multi")
    timing = {"model_path", "seconds_per_epoch"}
    assert {k: v for k, v in summary.items() if k not in timing} == \
        {k: v for k, v in expected.items() if k not in timing}
    assert summary["model_path"] == py_path and summary["epochs"] == 2
    # The same weights: the two files predict the same bits.
    x, u = batch(diffdyn.load_model(py_path), 20)
    assert np.array_equal(diffdyn.load_model(py_path).predict(x, u), diffdyn.load_model(cli_path).predict(x, u))


def test_train_refuses_bad_options(pendulum_files, tmp_path):
    data, _ = pendulum_files
    out = str(tmp_path / "m.json")
    with pytest.raises(ValueError, match="unknown option 'epoch'"):
        diffdyn.train(data, "abs-nn", out=out, epoch=3)
    with pytest.raises(ValueError, match="--epochs must be >= 1"):
        diffdyn.train(data, "abs-nn", out=out, epochs=0)
    with pytest.raises(TypeError, match="epochs"):
        diffdyn.train(data, "abs-nn", out=out, epochs="many")
    with pytest.raises(ValueError, match="--model"):
        diffdyn.train(data, "abs-ode", out=out)
    with pytest.raises(ValueError, match="also an input"):
        diffdyn.train(data, "abs-nn", out=data)
    assert not os.path.exists(out)


def test_two_python_threads_predict_at_once():
    panda = diffdyn.load_model("panda", dt=0.004)
    x, u = batch(panda, 200, 0.1)
    small = pendulum()
    xs, us = batch(small, 8)
    span, finished = [], []

    def long_call():
        start = time.perf_counter()
        panda.jacobian(x, u, threads=1)
        span.extend([start, time.perf_counter()])

    def short_calls():
        while not span:
            small.predict(xs, us, threads=1)
            finished.append(time.perf_counter())

    workers = [threading.Thread(target=long_call), threading.Thread(target=short_calls)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    start, end = span
    inside = sum(start < t < end for t in finished)
    # Had the long call held the GIL, no other thread could have finished a call
    # between its two clock readings.
    assert end - start > 0.02, "the call is too short to tell"
    assert inside >= 3, f"{inside} predictions finished during a {end - start:.3f} s jacobian call"
