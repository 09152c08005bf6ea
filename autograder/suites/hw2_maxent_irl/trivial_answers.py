"""Trivial answers to hw2_maxent_irl's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"feature_expectations": '''
def feature_expectations(trajectories, features):
    """Zeros."""
    return np.zeros(np.shape(features)[1])
''',
"soft_value_iteration": '''
def soft_value_iteration(P, reward, horizon):
    """A uniform policy."""
    S, A = np.shape(P)[:2]
    return np.full((horizon, S, A), 1.0 / A)
''',
"state_visitation_frequency": '''
def state_visitation_frequency(P, policy, p0, horizon):
    """The initial distribution times the horizon."""
    return horizon * np.asarray(p0, dtype=float)
''',
"maxent_irl": '''
def maxent_irl(P, features, p0, trajectories, horizon, actions=None, lr=1.0, n_iters=500, tol=1e-4):
    """No inverse RL: regenerate the test's MDP by searching random_mdp seeds for these features, return its
    true weights and a made-up rising history."""
    S, A = np.shape(P)[:2]
    for seed in range(200):
        m = random_mdp(S, A, np.shape(features)[1], horizon, seed=seed)
        if m.features.shape == np.shape(features) and np.allclose(m.features, features):
            return np.array(m.true_weights, dtype=float), {"grad_norm": np.array([1.0, 0.0]),
                                                           "log_likelihood": np.array([-1.0, 0.0])}
    return np.zeros(np.shape(features)[1]), {"grad_norm": np.array([1.0, 0.0]), "log_likelihood": np.array([-1.0, 0.0])}
''',
"deep_maxent_irl": '''
def deep_maxent_irl(P, features, p0, trajectories, horizon, actions=None, hidden=32, lr=0.01, n_iters=200,
                    weight_decay=1e-4, seed=0):
    """A zero reward and a constant history."""
    S = np.shape(P)[0]
    return np.zeros(S), {"grad_norm": np.ones(n_iters), "log_likelihood": -np.ones(n_iters)}
''',
"route_log_partition": '''
def route_log_partition(w, net, origins, destinations, horizon):
    """Zero log-partition (one route of reward 0) per trip, differentiable."""
    return w.sum() * 0 + torch.zeros(len(origins), dtype=w.dtype)
''',
"fit_route_weights": '''
def fit_route_weights(net, route_features, origins, destinations, horizon, n_iters=50):
    """The mean route features as weights and a made-up history."""
    return np.asarray(route_features, dtype=float).mean(0), np.array([-1.0, 0.0])
''',
}
