"""The sandbox room: everything that runs in a sandbox process, and the wire it speaks.

Three processes run code from this package, and each module says which:

- ``zygote``: the zygote (a pre-imported process forked from the grader) and the
  launcher it forks for each worker;
- ``isolation``: the launcher (namespaces) and the worker before it runs student
  code (the file-system view, resource limits, the privilege drop);
- ``worker``: the worker, which executes student cells and answers calls;
- ``wire`` and ``config``: plain data shared by both sides of the channel.

Nothing here imports the grader, the suites or the reference: a student's code
runs next to this package and must find nothing in it worth reading. The
grader's handle on workers lives outside, in :mod:`autograder.core.supervisor`.
"""
