"""Trivial answers to hw0_setup's stubs, each written to look plausible while doing none of the work.

The project's tests (tests/test_adversarial_suites.py) grade a notebook whose every stub is replaced by
its answer here and require that it earns nothing: each hidden test must pair its invariance with a value
such an answer gets wrong. Every stub of the assignment has one (``python -m autograder new`` writes them
for a new assignment). Not a test module: the grader collects ``test_*.py`` only.
"""
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
