"""The grading core (trusted): reading submissions, driving the sandbox, running suites, the result types.

It depends on the sandbox's protocol and never on :mod:`autograder.outputs` or
:mod:`autograder.authoring`: whoever writes outputs receives each result (a callback) and renders it.
"""
