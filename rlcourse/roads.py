"""A small road network for route prediction (hw2, part C).

The network is a graph of intersections joined by directed road segments
(*edges*). A route is a sequence of edges from an origin intersection to a
destination, and its features add up along it: kilometres driven on each road
class, toll segments used, and the left turns, right turns and U-turns made at
intersections. Because turns depend on *pairs* of consecutive edges, the state
of a driver is the edge just driven, and a *transition* ``k`` goes from edge
``trans_from[k]`` to edge ``trans_to[k]`` through their shared intersection.

Feature bookkeeping (``F = 7``, all counts or lengths, so never negative):

- ``edge_features[e]``: the features of driving edge ``e`` (turn columns zero);
- ``trans_features[k]``: ``edge_features[trans_to[k]]`` plus the turn made;
- the features of a route ``e_0, ..., e_m`` are
  ``edge_features[e_0] + sum_k trans_features[k_j]`` over its ``m`` transitions.

Padded lookup tables make vectorised dynamic programming easy:
``successors[e]`` lists the transitions out of edge ``e`` and ``out_edges[v]``
the edges leaving intersection ``v``, each padded with ``-1``.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import matplotlib.pyplot as plt
from matplotlib.collections import LineCollection
import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import dijkstra

from rlcourse import data

ROAD_CLASSES = ("highway", "arterial", "residential")
FEATURES = ("km highway", "km arterial", "km residential", "toll segments", "left turns", "right turns", "U-turns")
TURNS = ("straight", "left", "right", "U-turn")


@dataclass(frozen=True)
class RoadNetwork:
    """Intersections ``xy`` (V, 2) and directed edges ``tail -> head`` (E,) with their attributes."""

    xy: np.ndarray          # (V, 2) coordinates in km
    tail: np.ndarray        # (E,) start intersection of each edge
    head: np.ndarray        # (E,) end intersection of each edge
    road_class: np.ndarray  # (E,) index into ROAD_CLASSES
    toll: np.ndarray        # (E,) bool

    @property
    def n_nodes(self) -> int:
        return self.xy.shape[0]

    @property
    def n_edges(self) -> int:
        return self.tail.shape[0]

    @cached_property
    def length(self) -> np.ndarray:
        """(E,) segment lengths in km."""
        return np.linalg.norm(self.xy[self.head] - self.xy[self.tail], axis=1)

    @cached_property
    def trans_from(self) -> np.ndarray:
        """(K,) edge before each transition (transitions sorted by it)."""
        return self._transitions_cache[0]

    @cached_property
    def trans_to(self) -> np.ndarray:
        """(K,) edge after each transition."""
        return self._transitions_cache[1]

    @cached_property
    def _transitions_cache(self) -> tuple[np.ndarray, np.ndarray]:
        return self._transitions()

    def _transitions(self) -> tuple[np.ndarray, np.ndarray]:
        # every pair (e, e') with head(e) == tail(e'): e' leaves the intersection e arrives at
        order = np.argsort(self.tail, kind="stable")
        starts = np.searchsorted(self.tail[order], np.arange(self.n_nodes + 1))
        counts = np.diff(starts)[self.head]  # out-degree of each edge's head
        frm = np.repeat(np.arange(self.n_edges), counts)
        offsets = np.arange(frm.size) - np.repeat(np.cumsum(counts) - counts, counts)
        to = order[starts[self.head[frm]] + offsets]
        return frm, to

    @cached_property
    def turn(self) -> np.ndarray:
        """(K,) index into TURNS of the turn made by each transition."""
        frm, to = self._transitions_cache
        d_in = self.xy[self.head[frm]] - self.xy[self.tail[frm]]
        d_out = self.xy[self.head[to]] - self.xy[self.tail[to]]
        cross = d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0]
        angle = np.degrees(np.arctan2(cross, (d_in * d_out).sum(axis=1)))
        return np.select([np.abs(angle) > 150, angle > 35, angle < -35], [3, 1, 2], default=0)

    @cached_property
    def edge_features(self) -> np.ndarray:
        """(E, F) features of driving each edge (turn columns are zero)."""
        feats = np.zeros((self.n_edges, len(FEATURES)))
        feats[np.arange(self.n_edges), self.road_class] = self.length
        feats[:, 3] = self.toll
        return feats

    @cached_property
    def trans_features(self) -> np.ndarray:
        """(K, F) features of each transition: the next edge's features plus the turn."""
        feats = self.edge_features[self.trans_to].copy()
        turn = self.turn
        for j, column in ((1, 4), (2, 5), (3, 6)):
            feats[:, column] += turn == j
        return feats

    @cached_property
    def successors(self) -> np.ndarray:
        """(E, M) transition indices out of each edge, padded with -1."""
        return _padded_groups(self.trans_from, self.n_edges)

    @cached_property
    def out_edges(self) -> np.ndarray:
        """(V, M) edges leaving each intersection, padded with -1."""
        return _padded_groups(self.tail, self.n_nodes)

    def transition_index(self, route: np.ndarray) -> np.ndarray:
        """The transitions taken by a route (sequence of edges); raises if two edges do not connect."""
        route = np.asarray(route)
        candidates = self.successors[route[:-1]]                                   # (m, M)
        match = (candidates >= 0) & (self.trans_to[candidates] == route[1:, None])
        if not match.any(axis=1).all():
            raise ValueError(f"route is not connected at position {int(np.argmin(match.any(axis=1)))}")
        return candidates[np.arange(len(route) - 1), match.argmax(axis=1)]

    def route_features(self, route: np.ndarray) -> np.ndarray:
        """(F,) feature sum of one route (a sequence of edge indices)."""
        route = np.asarray(route)
        return self.edge_features[route[0]] + self.trans_features[self.transition_index(route)].sum(axis=0)

    def best_route(self, weights: np.ndarray, origin: int, destination: int) -> np.ndarray:
        """The route of highest reward ``weights . f(route)`` from ``origin`` to ``destination``.

        ``weights`` must make every cost ``-weights . f`` non-negative (Dijkstra on the edge graph).
        """
        return self.cheapest_route(-self.edge_features @ weights, -self.trans_features @ weights,
                                   origin, destination)

    def cheapest_route(self, edge_cost: np.ndarray, trans_cost: np.ndarray, origin: int,
                       destination: int) -> np.ndarray:
        """The route of least total cost: ``edge_cost[e_0]`` (E,) plus ``trans_cost`` (K,) of its transitions."""
        if (edge_cost < 0).any() or (trans_cost < 0).any():
            raise ValueError("route costs must be non-negative (rewards <= 0) on every edge and turn")
        n = self.n_edges
        start = self.out_edges[origin]
        start = start[start >= 0]
        # nodes 0..n-1 are edges (cost paid on entering), node n is the origin; tiny floor keeps zero costs as edges
        rows = np.concatenate([self.trans_from, np.full(start.size, n)])
        cols = np.concatenate([self.trans_to, start])
        costs = np.maximum(np.concatenate([trans_cost, edge_cost[start]]), 1e-12)
        graph = csr_array((costs, (rows, cols)), shape=(n + 1, n + 1))
        dist, pred = dijkstra(graph, indices=n, return_predecessors=True)
        arriving = np.flatnonzero(self.head == destination)
        e = int(arriving[np.argmin(dist[arriving])])
        if not np.isfinite(dist[e]):
            raise ValueError(f"no route from {origin} to {destination}")
        route = [e]
        while pred[route[-1]] != n:
            route.append(int(pred[route[-1]]))
        return np.array(route[::-1])

    def shortest_route(self, origin: int, destination: int) -> np.ndarray:
        """The route of least length (all road classes alike, turns free)."""
        return self.best_route(-np.array([1.0, 1.0, 1.0, 0, 0, 0, 0]), origin, destination)


def enumerate_routes(net: RoadNetwork, origin: int, destination: int, max_segments: int) -> list[np.ndarray]:
    """Every route of at most ``max_segments`` edges from ``origin`` that ends on its first arrival at
    ``destination`` (brute force, exponential in length: for checks on tiny networks only)."""
    found, stack = [], [[int(e)] for e in net.out_edges[origin] if e >= 0]
    while stack:
        route = stack.pop()
        if net.head[route[-1]] == destination:
            found.append(np.array(route))
        elif len(route) < max_segments:
            stack.extend(route + [int(net.trans_to[k])] for k in net.successors[route[-1]] if k >= 0)
    return found


def grid_network(rows: int, cols: int, seed: int = 0) -> RoadNetwork:
    """A small jittered grid of two-way streets with random road classes and tolls (for tests)."""
    rng = np.random.default_rng(seed)
    r, c = np.divmod(np.arange(rows * cols), cols)
    xy = np.stack([c, -r], axis=1) + rng.uniform(-0.15, 0.15, size=(rows * cols, 2))
    a = np.concatenate([np.flatnonzero(c < cols - 1), np.flatnonzero(r < rows - 1)])
    b = np.concatenate([np.flatnonzero(c < cols - 1) + 1, np.flatnonzero(r < rows - 1) + cols])
    road_class, toll = rng.integers(0, 3, size=a.size), rng.random(a.size) < 0.2
    return RoadNetwork(xy=xy, tail=np.concatenate([a, b]), head=np.concatenate([b, a]),
                       road_class=np.tile(road_class, 2), toll=np.tile(toll, 2))


def _padded_groups(keys: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, M) indices i with keys[i] == g in row g, padded with -1 (M = largest group)."""
    order = np.argsort(keys, kind="stable")
    counts = np.bincount(keys, minlength=n_groups)
    rank = np.arange(keys.size) - np.repeat(np.cumsum(counts) - counts, counts)
    table = np.full((n_groups, max(int(counts.max()), 1)), -1, dtype=np.int64)
    table[keys[order], rank] = order
    return table


@dataclass(frozen=True)
class RouteSet:
    """Demonstrated routes: ``routes[i]`` is an array of edges from ``origins[i]`` to ``destinations[i]``."""

    origins: np.ndarray       # (M,)
    destinations: np.ndarray  # (M,)
    routes: list[np.ndarray]
    test: np.ndarray          # (M,) bool: held out for evaluation
    true_weights: np.ndarray  # (F,) the drivers' average preference (hidden; for comparison only)


def load_network(name: str = "roads/network.npz") -> RoadNetwork:
    """The shipped road network (checksum verified)."""
    arrays = data.load_npz(name)
    return RoadNetwork(xy=arrays["xy"], tail=arrays["tail"], head=arrays["head"],
                       road_class=arrays["road_class"], toll=arrays["toll"].astype(bool))


def load_routes(name: str = "roads/routes.npz") -> RouteSet:
    """The shipped demonstrated routes (checksum verified)."""
    arrays = data.load_npz(name)
    routes = np.split(arrays["edges"], arrays["offsets"][1:-1])
    return RouteSet(origins=arrays["origins"], destinations=arrays["destinations"], routes=routes,
                    test=arrays["test"].astype(bool), true_weights=arrays["true_weights"])


def segment_overlap(predicted: np.ndarray, demonstrated: np.ndarray) -> float:
    """Fraction of the demonstrated route's segments that the predicted route also uses."""
    return float(np.isin(demonstrated, predicted).mean())


def plot_routes(net: RoadNetwork, routes: dict[str, np.ndarray], ax: plt.Axes | None = None,
                title: str | None = None) -> plt.Axes:
    """Draw the network (road classes by width, tolls in orange) and named routes on top."""
    ax = ax or plt.subplots(figsize=(5, 5))[1]
    seg = np.stack([net.xy[net.tail], net.xy[net.head]], axis=1)  # (E, 2, 2)
    for cls, width in zip(range(3), (2.5, 1.5, 0.6)):
        ax.add_collection(LineCollection(seg[net.road_class == cls], colors="0.75", linewidths=width, zorder=1))
    ax.add_collection(LineCollection(seg[net.toll], colors="orange", linewidths=2.5, zorder=2))
    styles = [("black", "-", 3.5), ("tab:blue", "--", 2.5), ("tab:red", ":", 2.5), ("tab:green", "-.", 2)]
    for (name, route), (color, ls, lw) in zip(routes.items(), styles):
        route = np.asarray(route)
        path = np.concatenate([net.xy[net.tail[route[:1]]], net.xy[net.head[route]]])
        ax.plot(path[:, 0], path[:, 1], color=color, linestyle=ls, linewidth=lw, label=name, zorder=3)
    first = np.asarray(next(iter(routes.values())))
    ax.scatter(*net.xy[net.tail[first[0]]], marker="o", s=60, color="k", zorder=4)
    ax.scatter(*net.xy[net.head[first[-1]]], marker="*", s=160, color="k", zorder=4)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.legend(frameon=False, fontsize=8, loc="upper left", bbox_to_anchor=(1, 1))
    if title:
        ax.set_title(title, fontsize=10)
    return ax
