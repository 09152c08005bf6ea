"""Trivial answers to hw0_setup's stubs: plausible, doing none of the work; each must earn nothing (CONTRIBUTING.md)."""
ANSWERS = {
"discounted_returns": '''
def discounted_returns(rewards, gamma):
    """The input handed back."""
    return np.array(rewards, dtype=float)
''',
"episode_returns": '''
def episode_returns(rewards, dones):
    """The rewards of the done steps only."""
    return np.asarray(rewards, dtype=float)[np.asarray(dones, dtype=bool)]
''',
}
