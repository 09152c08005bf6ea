"""The course's grader and instructor tools (see ``python -m autograder --help``)."""
import os as _os

# One BLAS thread per process: graders and sandboxes run side by side on few cores, where a
# multi-threaded BLAS spends more time contending than computing on the small arrays of tests.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")
