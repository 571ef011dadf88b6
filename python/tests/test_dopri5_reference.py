"""diffdyn's batched dopri5 against the PyTorch reference's (bench/torch_common.dopri5_flow,
the same error control written in torch) on the same weights: an abs-NODE trained one
epoch with --solver dopri5 on the pushing data, its predictions of the first 1, 50 and
200 transitions, in float64 and float32. In float64 the same accepted steps leave
rounding only and another step sequence would differ near the tolerance, 1e-8; in
float32 the model is first `stiffened` (output layer x 30, tolerance 1e-4) so that the
steps matter above float rounding. Skipped where torch is not installed."""

import os
import sys

import pytest

pytest.importorskip("torch")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench"))
import dopri5_reference_check  # noqa: E402

from conftest import run_cli  # noqa: E402


@pytest.mark.parametrize("precision", ["f64", "f32"])
def test_dopri5_takes_the_steps_of_the_torch_reference(tmp_path, precision):
    data = dopri5_reference_check.pushing_data()
    model = str(tmp_path / "dopri5.json")
    run_cli("train", "--data", data, "--model", "abs-node", "--solver", "dopri5", "--epochs", "1",
            "--precision", precision, "--quiet", "--out", model)
    if precision == "f32":
        dopri5_reference_check.stiffened(model, model)
    for n, accepted, rejected, diff in dopri5_reference_check.compare(model, data=data):
        assert accepted >= 1, f"{n} samples: no accepted step"
        assert diff <= dopri5_reference_check.TOLERANCE[precision], \
            f"{n} samples: diffdyn and PyTorch differ by {diff:.3g} ({accepted} + {rejected} steps)"
