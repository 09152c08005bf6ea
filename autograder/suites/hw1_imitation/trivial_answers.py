"""Trivial answers to hw1_imitation's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"bc_loss": '''
def bc_loss(policy, obs, actions):
    """A constant that keeps the graph: 0.5 log(2 pi) per action dimension."""
    return (policy(obs) * 0).sum() + policy.log_std.sum() * 0 + 0.5 * np.log(2 * np.pi) * actions.shape[-1]
''',
"train_bc": '''
def train_bc(policy, obs, actions, n_epochs=20, batch_size=256, lr=1e-3, val_fraction=0.1, seed=0):
    """No training, a made-up falling history."""
    return {"train": [float(n_epochs - e) for e in range(n_epochs)],
            "val": [float(n_epochs - e) + 0.5 for e in range(n_epochs)]}
''',
"relabel_with_expert": '''
def relabel_with_expert(expert, obs):
    """Zero actions of the Hopper's size."""
    obs = np.asarray(obs, dtype=np.float32)
    return np.zeros(obs.shape[:-1] + (3,), dtype=np.float32)
''',
"dagger": '''
def dagger(env_id, expert, policy, n_iterations, beta_schedule, demo_obs, demo_actions, episodes_per_iter=2, seed=0,
           **train_kwargs):
    """The untrained learner, the demonstrations as the data set, a made-up history."""
    n = len(demo_obs)
    return policy, {"returns": np.zeros(n_iterations), "dataset_sizes": np.full(n_iterations, n, dtype=np.int64),
                    "obs": np.asarray(demo_obs, dtype=np.float32), "actions": np.asarray(demo_actions, dtype=np.float32)}
''',
}
