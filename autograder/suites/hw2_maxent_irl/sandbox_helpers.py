"""hw2's suite helpers: run in the sandbox, beside the submission (see ``autograder/suites/sandbox_common.py``).

``notebook`` is the submission's namespace (set by the worker). They hold no answer: the one stand-in here asks the
grader, through an object it lends, for the reference's values and gradients.
"""
from contextlib import contextmanager

import numpy as np


@contextmanager
def _log_partition_stands_in(model):
    """The notebook's ``route_log_partition`` replaced, for the duration, by the grader's reference, reached through
    ``model`` (lent: ``log_z`` and ``vjp`` run in the grader on plain data) and wrapped as a torch autograd function,
    so that gradients flow into the weights as through the student's own. The grader's automatic stand-ins take plain
    data only, and fit_route_weights calls route_log_partition with weights that need gradients."""
    import torch

    class LogZ(torch.autograd.Function):
        @staticmethod
        def forward(ctx, w, origins, destinations, horizon):
            ctx.query = (w.detach().numpy().copy(), np.asarray(origins), np.asarray(destinations), int(horizon))
            return torch.as_tensor(np.asarray(model.log_z(*ctx.query)), dtype=torch.float64)

        @staticmethod
        def backward(ctx, grad_output):
            vjp = model.vjp(*ctx.query, grad_output.detach().numpy().astype(np.float64))
            return torch.as_tensor(np.asarray(vjp), dtype=torch.float64), None, None, None

    def route_log_partition(weights, net, origins, destinations, horizon):
        return LogZ.apply(torch.as_tensor(weights, dtype=torch.float64), origins, destinations, horizon)

    with standing_in(route_log_partition=route_log_partition):  # noqa: F821 - sandbox_common's, same module
        yield


def run_fit_route_weights(model, *args, **kwargs):
    """The submission's ``fit_route_weights``, with the reference's log-partition (through the lent ``model``)
    standing in for the ``route_log_partition`` it calls."""
    with _log_partition_stands_in(model):
        return notebook["fit_route_weights"](*args, **kwargs)  # noqa: F821
