"""Tests of rlcourse.roads and the shipped road data."""
import numpy as np
import pytest
from scipy.special import logsumexp

from rlcourse.roads import FEATURES, enumerate_routes, grid_network, load_network, load_routes, segment_overlap


def test_transitions_and_turns_on_a_grid():
    net = grid_network(2, 2, seed=0)
    # 4 two-way blocks -> 8 edges; every edge continues through 2 edges at its head (one is the U-turn)
    assert net.n_edges == 8 and net.trans_from.size == 16
    assert np.all(net.head[net.trans_from] == net.tail[net.trans_to])
    assert np.all((net.turn == 3) == (net.head[net.trans_to] == net.tail[net.trans_from]))
    assert set(net.turn) <= {0, 1, 2, 3}
    assert (net.successors >= 0).sum() == 16 and (net.out_edges >= 0).sum() == 8


def test_route_features_add_up():
    net = grid_network(2, 3, seed=2)
    route = enumerate_routes(net, 0, 5, 3)[0]
    feats = net.route_features(route)
    assert feats.shape == (len(FEATURES),)
    assert feats[:3].sum() == pytest.approx(net.length[route].sum())
    assert feats[4:].sum() == len(route) - 1 - np.sum(net.turn[net.transition_index(route)] == 0)
    with pytest.raises(ValueError, match="not connected"):
        net.transition_index(np.array([route[0], route[0]]))


def test_best_route_is_the_most_likely_enumerated_route():
    net = grid_network(3, 3, seed=1)
    w = -np.array([0.5, 1.0, 2.0, 1.0, 0.7, 0.2, 3.0])
    routes = enumerate_routes(net, 0, 8, 8)
    scores = np.array([net.route_features(r) @ w for r in routes])
    best = net.best_route(w, 0, 8)
    assert net.route_features(best) @ w == pytest.approx(scores.max())
    assert logsumexp(scores) >= scores.max()
    with pytest.raises(ValueError, match="non-negative"):
        net.best_route(-w, 0, 8)


def test_shipped_data_is_consistent():
    net, trips = load_network(), load_routes()
    assert 200 <= net.n_nodes <= 400 and len(trips.routes) == 600 and trips.test.sum() == 150
    for o, d, r in zip(trips.origins[:50], trips.destinations[:50], trips.routes[:50]):
        assert net.tail[r[0]] == o and net.head[r[-1]] == d and (net.head[r[:-1]] != d).all()
        net.transition_index(r)  # connected
    assert segment_overlap(trips.routes[0], trips.routes[0]) == 1.0
