"""Hidden tests of route_log_partition (brute-force enumeration and the reference).

rlcourse ships the brute force (``enumerate_routes``), so each test that checks against it also asks for
log Z on a 5 x 5 grid at horizon 30, whose routes are far too many to enumerate (a 4 x 4 grid at horizon
12 already has 39,816), checked against the reference: only the soft backward pass gets through.
"""
import numpy as np
import torch
from scipy.special import logsumexp

from autograder.suite import check_tensor, stub
from rlcourse.roads import enumerate_routes, grid_network, load_network, load_routes

HINT = ("Values of shape (D, E) for the distinct destinations: 0 on edges arriving at d, else logsumexp over "
        "net.successors of (transition reward + value of the next edge), horizon - 1 times; then logsumexp over "
        "net.out_edges[o] of (edge reward + value). Mask the -1 padding, and keep everything in torch.")
NETWORK = "rlcourse.roads.RoadNetwork"


def _network(ns, net):
    """The road network ``net``, rebuilt from its arrays with the release's RoadNetwork on that side (a handle)."""
    return ns.helpers.build(NETWORK, xy=net.xy, tail=net.tail, head=net.head, road_class=net.road_class, toll=net.toll)


def _log_z(ns, net, w, origins, destinations, horizon):
    """log Z of each trip, by that side's ``route_log_partition``."""
    return ns.route_log_partition(torch.tensor(w), _network(ns, net), origins, destinations, horizon)


def _grad_log_z(ns, net, w, origins, destinations, horizon):
    """d (sum of log Z over the trips) / d w, by autograd through that side's ``route_log_partition``."""
    args = [torch.tensor(w), _network(ns, net), origins, destinations, horizon]
    return ns.helpers.grad("route_log_partition", args, wrt=[0], grad_outputs=torch.ones(len(origins)))[0]


def _brute(net, w, origin, destination, horizon):
    return logsumexp([net.route_features(r) @ w for r in enumerate_routes(net, origin, destination, horizon)])


BIG = grid_network(5, 5, seed=9)
BIG_TRIPS = dict(origins=np.array([0, 3, 24, 12]), destinations=np.array([24, 20, 0, 4]), horizon=30)


def _check_too_big_to_enumerate(student, reference, w, fn=_log_z, name="log Z"):
    """The same call on the 5 x 5 grid at horizon 30, against the reference."""
    check_tensor(fn(student, BIG, w, **BIG_TRIPS), fn(reference, BIG, w, **BIG_TRIPS), rtol=1e-7, atol=1e-9,
                 name=f"{name} on a 5 x 5 grid at horizon 30 (too many routes to enumerate)")


@stub("route_log_partition", points=2, hint=HINT)
def test_matches_brute_force(student, reference, rng):
    """On a 2 x 3 and a 3 x 3 grid, several origin-destination pairs at once, horizons 5 and 7; and a 5 x 5 grid"""
    for rows, cols, horizon in ((2, 3, 7), (3, 3, 5)):
        net = grid_network(rows, cols, seed=rows)
        w = -rng.uniform(0.2, 2.0, size=7)
        origins, destinations = np.array([0, 1, rows * cols - 1, 0]), np.array([rows * cols - 1, cols, 0, cols])
        want = torch.tensor([_brute(net, w, o, d, horizon) for o, d in zip(origins, destinations)])
        got = _log_z(student, net, w, origins, destinations, horizon)
        check_tensor(got, want, rtol=1e-7, atol=1e-9, name=f"log Z on a {rows} x {cols} grid (H = {horizon})")
    _check_too_big_to_enumerate(student, reference, -rng.uniform(0.2, 2.0, size=7))


@stub("route_log_partition", points=1, hint=HINT)
def test_positive_weights_and_loops(student, reference, rng):
    """Weights that make loops attractive stay finite (routes are capped at H segments)"""
    net = grid_network(2, 2, seed=0)
    w = rng.uniform(0.1, 1.0, size=7)
    want = torch.tensor([_brute(net, w, 0, 3, 6)])
    got = _log_z(student, net, w, np.array([0]), np.array([3]), 6)
    check_tensor(got, want, rtol=1e-7, name="log Z with positive rewards")
    _check_too_big_to_enumerate(student, reference, rng.uniform(0.1, 1.0, size=7), name="log Z with positive rewards")


@stub("route_log_partition", points=1, hint=HINT)
def test_shipped_network_matches_reference(student, reference, rng):
    """The shipped network, 30 trips to mixed destinations, weights scaled by 1 and by 40"""
    net, trips = load_network(), load_routes()
    idx = rng.choice(len(trips.origins), size=30, replace=False)
    for scale in (1.0, 40.0):
        w = scale * trips.true_weights
        args = dict(origins=trips.origins[idx], destinations=trips.destinations[idx], horizon=45)
        check_tensor(_log_z(student, net, w, **args), _log_z(reference, net, w, **args), rtol=1e-7, atol=1e-7,
                     name=f"log Z with the weights scaled by {scale:g}")


@stub("route_log_partition", points=1, hint=HINT)
def test_gradient_is_expected_features(student, reference, rng):
    """Autograd through log Z gives the expected route features (brute force; and the reference on a 5 x 5 grid)"""
    net = grid_network(2, 3, seed=4)
    w = -rng.uniform(0.2, 2.0, size=7)
    routes = enumerate_routes(net, 0, 5, 6)
    feats = np.stack([net.route_features(r) for r in routes])
    p = np.exp(feats @ w - logsumexp(feats @ w))
    got = _grad_log_z(student, net, w, np.array([0]), np.array([5]), 6)
    check_tensor(got, torch.tensor(p @ feats), rtol=1e-6, atol=1e-9, name="the gradient of log Z")
    _check_too_big_to_enumerate(student, reference, -rng.uniform(0.2, 2.0, size=7), fn=_grad_log_z, name="the gradient of log Z")
