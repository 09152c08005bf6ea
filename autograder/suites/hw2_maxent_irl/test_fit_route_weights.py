"""Hidden tests of fit_route_weights."""
import numpy as np
import torch

from autograder.suite import lend, stub
from rlcourse.roads import load_network, load_routes

HINT = ("mu_D = mean route features; maximise w . mu_D - mean(route_log_partition(w, ...)) from w = 0 with "
        "torch.optim.LBFGS(line_search_fn='strong_wolfe'); return (w as a numpy array, history).")
NETWORK = "rlcourse.roads.RoadNetwork"
_CACHE = {}


def _data(n, max_segments, rng_seed=0):
    """``n`` training trips drawn among those whose route has at most ``max_segments`` segments (a horizon a little
    above that holds every route, and the backward pass costs in proportion to the horizon)."""
    if (n, max_segments) not in _CACHE:
        net, trips = load_network(), load_routes()
        pool = [i for i in np.flatnonzero(~trips.test) if len(trips.routes[i]) <= max_segments]
        idx = np.random.default_rng(rng_seed).choice(pool, size=n, replace=False)
        feats = np.stack([net.route_features(trips.routes[i]) for i in idx])
        _CACHE[n, max_segments] = net, feats, trips.origins[idx], trips.destinations[idx]
    return _CACHE[n, max_segments]


def _network(ns, net):
    """The road network ``net``, rebuilt from its arrays with the release's RoadNetwork on that side (a handle)."""
    return ns.helpers.build(NETWORK, xy=net.xy, tail=net.tail, head=net.head, road_class=net.road_class, toll=net.toll)


def _loglik_and_gradient(reference, net, w, feats, origins, destinations, horizon):
    """The mean log-likelihood at w and the model's expected features there (reference, trusted side)."""
    args = [torch.tensor(np.asarray(w, dtype=float)), _network(reference, net), origins, destinations, horizon]
    log_z, (grad,) = reference.helpers.value_and_grad("route_log_partition", args, wrt=[0],
                                                      grad_outputs=torch.full((len(origins),), 1 / len(origins)))
    mean_log_z, expected = float(log_z.mean()), grad.numpy()
    return float(feats.mean(axis=0) @ w - mean_log_z), np.asarray(expected)


def _magnitude(x):
    """How far, as an order of magnitude only (never the value itself)."""
    x = abs(float(x))
    return "less than 0.01" if x < 0.01 else f"of the order of {10.0 ** np.floor(np.log10(x)):g}"


class _ReferenceLogPartition:
    """The reference's route_log_partition on ``net``, lent to the sandbox while the student's fit_route_weights runs:
    log Z of a query, and its vector-Jacobian product in the weights (plain data both ways). The grader's automatic
    stand-ins take plain data only, and the fit calls route_log_partition with weights that need gradients, so
    without this the student's own ran (a correct fit beside a missing route_log_partition scored 0/3)."""

    def __init__(self, reference, net) -> None:
        self.reference, self.network, self.closed = reference, _network(reference, net), False

    def _open(self) -> None:
        """A lent object stays registered after its test: one kept by the submission must not answer later tests
        (route_log_partition's, on the same shipped network)."""
        if self.closed:
            raise RuntimeError("this stand-in served one call of fit_route_weights and is closed")

    def log_z(self, w, origins, destinations, horizon):
        self._open()
        out = self.reference.route_log_partition(torch.tensor(np.asarray(w, dtype=float)), self.network, origins,
                                                 destinations, horizon)
        return out.detach().numpy()

    def vjp(self, w, origins, destinations, horizon, grad_output):
        self._open()
        args = [torch.tensor(np.asarray(w, dtype=float)), self.network, origins, destinations, horizon]
        _, (grad,) = self.reference.helpers.value_and_grad("route_log_partition", args, wrt=[0],
                                                           grad_outputs=torch.as_tensor(grad_output))
        return grad.numpy()


def _call(client, net, feats, origins, destinations, horizon, n_iters=60, reference=None):
    """``client``'s fit; for the student's (``reference`` given), with the reference's log-partition standing in."""
    if reference is None:
        return client.fit_route_weights(_network(client, net), feats, origins, destinations, horizon, n_iters=n_iters)
    model = _ReferenceLogPartition(reference, net)
    try:
        return client.helpers.run_fit_route_weights(lend(model, methods=["log_z", "vjp"]), _network(client, net), feats,
                                                    origins, destinations, horizon, n_iters=n_iters)
    finally:
        model.closed = True


@stub("fit_route_weights", points=2, hint=HINT)
def test_reaches_the_maximum_likelihood(student, reference):
    """Its weights reach the reference's log-likelihood (within 1e-3) and match expected features"""
    # 12 trips of at most 12 segments at a horizon of 12: a sixth of the cost of 20 trips at 30 (the reference's fit
    # 0.43 s of CPU instead of 2.6), and the maximum is still one the optimiser must run to convergence to reach (the
    # reference stopped after 20 LBFGS iterations is 0.0019 below it, after 30 within 1e-5).
    net, feats, origins, destinations = _data(12, 12)
    w, hist = _call(student, net, feats, origins, destinations, 12, reference=reference)
    w = np.asarray(w, dtype=float)
    assert w.shape == (7,), f"the weights should have shape (F,) = (7,), got {w.shape}"
    w_ref, _ = _call(reference, net, feats, origins, destinations, 12)
    got, expected = _loglik_and_gradient(reference, net, w, feats, origins, destinations, 12)
    want, _ = _loglik_and_gradient(reference, net, np.asarray(w_ref), feats, origins, destinations, 12)
    assert got >= want - 1e-3, (f"the mean log-likelihood at your weights is {_magnitude(want - got)} below the "
                                "maximum (0.001 is allowed): run the optimiser to convergence on the mean, not the sum")
    gap = np.abs(feats.mean(axis=0) - expected).max()
    assert gap < 2e-2, f"expected route features differ from the data's by {gap:.3f} at your weights"


@stub("fit_route_weights", points=1, hint=HINT)
def test_history_rises(student, reference):
    """The recorded log-likelihood starts at its value at w = 0 and ends higher"""
    # A contract check, not a second fit to convergence: 5 trips of at most 12 segments, horizon 12, 4 iterations.
    net, feats, origins, destinations = _data(5, 12)
    w, hist = _call(student, net, feats, origins, destinations, 12, n_iters=4, reference=reference)
    hist = np.asarray(hist, dtype=float)
    assert hist.ndim == 1 and hist.size >= 2, f"the history should be a 1-D array of log-likelihoods, got shape {hist.shape}"
    at_zero, _ = _loglik_and_gradient(reference, net, np.zeros(feats.shape[1]), feats, origins, destinations, 12)
    assert np.isclose(hist[0], at_zero, rtol=1e-6), (
        f"the first entry should be the mean log-likelihood per trip at w = 0; yours is {_magnitude(hist[0] - at_zero)} "
        f"{'above' if hist[0] > at_zero else 'below'} it (record before the first step, and average over trips)")
    assert hist[-1] > hist[0], "the recorded log-likelihood should end higher than it starts"
    w = np.asarray(w, dtype=float)
    assert w.shape == (feats.shape[1],), f"the weights should have shape (F,) = ({feats.shape[1]},), got {w.shape}"
    reached, _ = _loglik_and_gradient(reference, net, w, feats, origins, destinations, 12)
    assert reached > at_zero + 0.1 * (hist[-1] - hist[0]), (
        "the mean log-likelihood at the returned weights (computed by the grader) is not above its value at w = 0 "
        "by the rise the history records: return the weights the optimiser reached")
