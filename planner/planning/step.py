"""One step of section 8.5: the cycle of figure 6 for one leg, as attempted.

A step moves the body on the current leaf of S0 onto the three other legs (Theta1 or
Theta2), lifts the leg, swings it and places it with Theta3 (S0 -> S_if -> S0).
:class:`Step` records one attempt, made by :meth:`planner.planning.local.LocalPlanner.step`
and timed by :meth:`planner.planning.local.LocalPlanner.step_samples`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from planner.body.state import State

__all__ = ["Step"]


@dataclass
class Step:
    """The outcome of one step attempt for ``leg`` from ``start``.

    ``moved``: the state after the body move (None if it failed); ``end``: after the
    placement, back on S0 (None if the step failed). ``phase`` names the failed part
    ("body_move" or "foot_placement"), ``diagnosis`` says why and ``failure`` holds the
    kinds of what failed (:class:`planner.core.failures.FailureKind`), for the planner.
    """

    leg: int
    ok: bool
    start: State
    moved: State | None
    end: State | None
    body_path: list[State]
    swing_path: list[State]
    phase: str = ""
    diagnosis: str = ""
    # the swing overlapping the body move (planner.planning.overlap), set by step_samples
    overlap: object = field(default=None, repr=False)
    timed: bool = field(default=False, repr=False)
    failure: tuple = ()  # FailureKind values of the failed part
