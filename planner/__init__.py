"""stratawalk: quasi-static quadruped planning in a stratified configuration space."""

import os as _os

# One BLAS thread unless the user says otherwise (before numpy is first imported): the
# planner's matrices are small (a relief's cosine sums: (N, 40) x (40, M)), and OpenBLAS's
# threads spinning against a busy machine made rough2cm's planning 33-41 s instead of
# 14-16 s beside a benchmark (2 cores, side by side).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
