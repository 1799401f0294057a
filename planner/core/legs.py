"""The legs' names, in the paper's order of legs 1..4 (0-based indices here).

A module of its own with no import, so that light modules (the command line's settings,
the gait queue, plots) name legs without loading Pinocchio through :mod:`planner.body.robot`.
"""

LEG_NAMES = ("FL", "FR", "HL", "HR")  # the paper's legs 1..4

__all__ = ["LEG_NAMES"]
