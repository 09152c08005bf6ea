"""Make the road network and the demonstrated routes of hw2 part C.

    python datasets/scripts/make_roads.py --seed 0

Writes ``datasets/roads/network.npz`` (a jittered 16 x 16 grid of intersections, 1 km
apart, with a ring highway, arterial avenues, residential streets, a few missing
blocks and a toll section on the highway) and ``datasets/roads/routes.npz`` (600
routes to 16 destinations, a quarter held out), then records both in the MANIFEST.

How the drivers choose. Each trip has its own driver, whose costs per feature are the
hidden average preference times a log-normal factor (people differ), and who also
perceives each road segment's cost with log-normal noise (local knowledge, traffic).
The driver takes the cheapest route under those perceived costs. This random-utility
model is *not* the maximum-entropy model that the course fits to these routes, much as
real drivers are not.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components

from rlcourse.data import DATASETS, record
from rlcourse.roads import RoadNetwork

SIDE = 16
TRUE_WEIGHTS = -np.array([0.35, 0.7, 1.2, 1.5, 0.6, 0.25, 4.0])  # rewards per km, toll segment, turn
N_DESTINATIONS, N_ROUTES, TEST_FRACTION = 16, 600, 0.25
PREFERENCE_SPREAD, PERCEPTION_NOISE = 0.25, 0.3


def make_network(rng: np.random.Generator) -> RoadNetwork:
    rows, cols = np.divmod(np.arange(SIDE * SIDE), SIDE)
    xy = np.stack([cols, SIDE - 1 - rows], axis=1) + rng.uniform(-0.2, 0.2, size=(SIDE * SIDE, 2))
    # undirected blocks: horizontal then vertical neighbours
    right = np.flatnonzero(cols < SIDE - 1)
    down = np.flatnonzero(rows < SIDE - 1)
    a = np.concatenate([right, down])
    b = np.concatenate([right + 1, down + SIDE])
    ra, ca, rb, cb = rows[a], cols[a], rows[b], cols[b]
    ring = {1, SIDE - 2}
    highway = ((ra == rb) & np.isin(ra, list(ring)) & (np.minimum(ca, cb) >= 1) & (np.maximum(ca, cb) <= SIDE - 2)) | \
              ((ca == cb) & np.isin(ca, list(ring)) & (np.minimum(ra, rb) >= 1) & (np.maximum(ra, rb) <= SIDE - 2))
    arterial = ~highway & (((ra == rb) & (ra % 5 == 3)) | ((ca == cb) & (ca % 5 == 3)))
    road_class = np.where(highway, 0, np.where(arterial, 1, 2))
    toll = highway & (ca == cb) & (ca == SIDE - 2)  # the east side of the ring is tolled
    # remove some residential blocks, keeping the network connected
    keep = np.ones(a.size, dtype=bool)
    for i in rng.permutation(np.flatnonzero(road_class == 2))[: int(0.12 * a.size)]:
        keep[i] = False
        graph = csr_array((np.ones(keep.sum()), (a[keep], b[keep])), shape=(SIDE * SIDE,) * 2)
        if connected_components(graph, directed=False)[0] > 1:
            keep[i] = True
    a, b, road_class, toll = a[keep], b[keep], road_class[keep], toll[keep]
    return RoadNetwork(xy=xy, tail=np.concatenate([a, b]), head=np.concatenate([b, a]),
                       road_class=np.tile(road_class, 2), toll=np.tile(toll, 2))


def make_routes(net: RoadNetwork, rng: np.random.Generator) -> dict[str, np.ndarray]:
    destinations = rng.choice(net.n_nodes, size=N_DESTINATIONS, replace=False)
    origins, dests, routes = [], [], []
    while len(routes) < N_ROUTES:
        d = destinations[len(routes) % N_DESTINATIONS]
        o = int(rng.integers(net.n_nodes))
        if np.linalg.norm(net.xy[o] - net.xy[d]) < 5.0:
            continue
        weights = TRUE_WEIGHTS * rng.lognormal(0.0, PREFERENCE_SPREAD, size=TRUE_WEIGHTS.size)
        noise = rng.lognormal(0.0, PERCEPTION_NOISE, size=net.n_edges)
        edge_cost = -(net.edge_features @ weights) * noise
        trans_cost = -(net.trans_features @ weights) * noise[net.trans_to]
        origins.append(o)
        dests.append(d)
        routes.append(net.cheapest_route(edge_cost, trans_cost, o, d))
    lengths = np.array([len(r) for r in routes])
    test = np.zeros(N_ROUTES, dtype=bool)
    test[rng.choice(N_ROUTES, size=int(TEST_FRACTION * N_ROUTES), replace=False)] = True
    return {"origins": np.array(origins), "destinations": np.array(dests), "edges": np.concatenate(routes),
            "offsets": np.concatenate([[0], np.cumsum(lengths)]), "test": test, "true_weights": TRUE_WEIGHTS}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    net = make_network(rng)
    routes = make_routes(net, rng)
    out = Path(DATASETS) / "roads"
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / "network.npz", xy=net.xy, tail=net.tail, head=net.head,
                        road_class=net.road_class, toll=net.toll)
    np.savez_compressed(out / "routes.npz", **routes)
    record(out / "network.npz", __file__, argv, seed=args.seed,
           info={"intersections": net.n_nodes, "segments": net.n_edges, "transitions": int(net.trans_from.size)})
    record(out / "routes.npz", __file__, argv, seed=args.seed,
           info={"routes": N_ROUTES, "destinations": N_DESTINATIONS, "held_out": int(routes["test"].sum()),
                 "mean_segments": float(np.diff(routes["offsets"]).mean())})
    print(f"{net.n_nodes} intersections, {net.n_edges} segments, {net.trans_from.size} transitions; "
          f"{N_ROUTES} routes, mean {np.diff(routes['offsets']).mean():.1f} segments")


if __name__ == "__main__":
    main()
