"""stratawalk: quasi-static quadruped planning in a stratified configuration space."""

import os as _os

# One BLAS thread unless the user says otherwise (before numpy is first imported): the
# planner's matrices are small (a relief's cosine sums: (N, 40) x (40, M)), and OpenBLAS's
# threads spinning against a busy machine more than doubled planning times (measured
# beside a benchmark on 2 cores).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"

# The layers, from the bottom up: a module imports only from its own layer or the layers
# below it, and no import forms a cycle (tests/test_layers.py reads every import).
LAYERS = (
    "core",  # errors, interrupts, output files, the machine, Lie groups, leg names
    "world",  # terrain as an implicit surface (section 5), height fields, course generator
    "body",  # the robot: URDF, kinematics and IK (4), contact, statics (6), torques, links
    "motion",  # trajectory tau, interpolation along leaves, footholds, swings, time law
    "problems",  # the Theta problems (7) in CasADi + IPOPT, and their options
    "planfile",  # the plan file: Plan, the independent check, export
    "planning",  # local planners (8.1, 8.2, 8.5), the gait-queue driver, global planning (9)
    "sim",  # MuJoCo model (10), execution open loop, with feedback (8.3) and correction (8.4)
    "replay",  # meshcat and HTML replay, plots
    "bench",  # benchmarks and the batch runner
    "cli",  # the command line
)
