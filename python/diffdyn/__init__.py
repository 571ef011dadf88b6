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

Bad input raises ValueError with the command line's message; a numerical failure
(a prediction that overflows) raises RuntimeError. The native work runs with the
GIL released, on all cores unless `threads` says otherwise; results do not depend
on the thread count. `diffdyn.torch_function` makes a model callable from PyTorch.
"""

from ._diffdyn import Model, __version__, evaluate, load_model, train

__all__ = ["Model", "evaluate", "load_model", "train", "__version__"]
