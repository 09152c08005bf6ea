"""Trivial answers to hw3_preferences's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"bt_probability": '''
def bt_probability(r_i, r_j):
    """A constant probability of one half."""
    return np.full(np.broadcast(np.asarray(r_i), np.asarray(r_j)).shape, 0.5)
''',
"bt_loss": '''
def bt_loss(utilities, i, j, mu):
    """log 2, the loss at equal utilities."""
    return float(np.log(2))
''',
"bt_gradient": '''
def bt_gradient(utilities, i, j, mu):
    """Zeros."""
    return np.zeros(np.shape(utilities))
''',
"fit_bradley_terry": '''
def fit_bradley_terry(n_items, i, j, mu, lr=None, n_steps=5000, tol=1e-9):
    """Zero utilities."""
    return np.zeros(n_items)
''',
"fit_bradley_terry_mm": '''
def fit_bradley_terry_mm(n_items, i, j, mu, n_iters=5000, tol=1e-10):
    """Centred win counts."""
    w = np.bincount(np.asarray(i), np.asarray(mu, dtype=float), minlength=n_items)
    return w - w.mean()
''',
"plackett_luce_loss": '''
def plackett_luce_loss(scores, rankings):
    """A constant."""
    return 1.0
''',
"condorcet_winner": '''
def condorcet_winner(P):
    """Never a winner."""
    return None
''',
"copeland_winner": '''
def copeland_winner(P):
    """Arm 0."""
    return 0
''',
"borda_winner": '''
def borda_winner(P):
    """Arm 0."""
    return 0
''',
"rucb": '''
def rucb(env, horizon, alpha=0.51, rng=None):
    """Uniform random duels."""
    rng = np.random.default_rng(0) if rng is None else rng
    pairs = rng.integers(0, env.n_arms, size=(horizon, 2))
    for c, d in pairs:
        env.duel(int(c), int(d))
    return pairs.astype(np.int64)
''',
"segment_return": '''
def segment_return(reward_model, obs, act):
    """Zero returns that keep the graph."""
    r = reward_model(obs, act)
    return r.sum(-1) * 0
''',
"preference_loss": '''
def preference_loss(returns_a, returns_b, mu):
    """log 2 whatever the returns."""
    return (returns_a * 0).sum() + (returns_b * 0).sum() + float(np.log(2))
''',
"train_reward_model": '''
def train_reward_model(obs, act, pairs, mu, n_members=3, hidden=(64, 64), n_steps=500, batch_size=64, lr=1e-3,
                       weight_decay=0.1, seed=0):
    """An untrained ensemble, normalised."""
    obs, act = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(act, dtype=torch.float32)
    used = np.unique(np.asarray(pairs))
    ensemble = RewardEnsemble(obs.shape[-1], act.shape[-1], n_members, hidden, seed=seed)
    ensemble.set_input_scaling(obs[used], act[used])
    return ensemble.normalise_(obs[used], act[used])
''',
"select_queries": '''
def select_queries(ensemble, obs, act, candidates, k):
    """The first k candidates."""
    return np.arange(k)
''',
"ratings_to_comparisons": '''
def ratings_to_comparisons(annotator, segment, rating, window=5):
    """Consecutive ratings, whoever gave them."""
    segment, rating = np.asarray(segment), np.asarray(rating, dtype=float)
    pairs = np.stack([segment[:-1], segment[1:]], 1).astype(np.int64)
    return pairs, 0.5 + 0.5 * np.sign(rating[:-1] - rating[1:])
''',
}
