"""Errors raised by stratawalk: one hierarchy under :class:`PlannerError`.

Every message names the file or field at fault and says what to do.
"""


class PlannerError(Exception):
    """Base class of every error stratawalk raises on purpose."""


class InputError(PlannerError, ValueError):
    """A user-supplied file or value is malformed (names file, field, fix)."""


class RobotModelError(InputError):
    """A URDF is missing, malformed, or not a 4-leg, 3-joints-per-leg quadruped."""


class TerrainError(InputError):
    """A terrain spec or height-field file is malformed."""


class OutputError(PlannerError):
    """An output could not be written after the work; ``kept``: where the result went instead."""

    def __init__(self, message: str, kept=None):
        super().__init__(message)
        self.kept = kept


class NoSolutionFound(PlannerError):
    """An optimisation problem has no feasible solution; carries the diagnosis."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result
