"""Trivial answers to hw1b_multimodal's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"chunked_rollout": '''
def chunked_rollout(plan, env, execute):
    """Zero actions until every episode ends, plan never called."""
    obs = np.asarray(env.reset(), dtype=np.float32)
    n = len(obs)
    rec, done = [], np.zeros(n, dtype=bool)
    while not done.all():
        a = np.zeros((n, 1), dtype=np.float32)
        nxt, r, te, tr = env.step(a)
        rec.append((obs, a, np.asarray(r), ~done))
        done = done | te | tr
        obs = np.asarray(nxt, dtype=np.float32)
    o, a, r, m = (np.stack(x, axis=1) for x in zip(*rec))
    return Episodes(o * m[..., None], a, r * m, m, m.sum(1), np.zeros(n, dtype=bool))
''',
"mode_coverage": '''
def mode_coverage(sides, expert_sides):
    """A constant."""
    if len(sides) == 0 or len(expert_sides) == 0:
        raise ValueError("empty")
    return {"left": 0.5, "right": 0.5, "not_passed": 0.0, "coverage": 1.0}
''',
"mixture_nll": '''
def mixture_nll(logits, means, log_stds, targets):
    """A constant that keeps the graph."""
    return (logits * 0).sum() + (means * 0).sum() + (log_stds * 0).sum() + float(np.log(2 * np.pi))
''',
"flow_matching_loss": '''
def flow_matching_loss(velocity, obs, chunks, noise, t):
    """The velocity's mean square, without a target."""
    v = velocity(noise, t, obs)
    return (v ** 2).sum(dim=tuple(range(1, v.dim()))).mean()
''',
"euler_sample": '''
def euler_sample(velocity, obs, noise, n_steps):
    """Noise only."""
    return noise.clone()
''',
}
