"""Why a step, a path or a Theta problem failed, as a typed kind the planners branch on.

A planner decides what to try next from the kind of a failure (a COM that lacks the
balance margin: no other foothold helps; a leg link nearer an edge than its path margin:
try a via pose), never from its message, which is for people.
"""

from __future__ import annotations

from enum import Enum

__all__ = ["FailureKind", "Problem", "kind_of", "kinds_of_groups"]


class FailureKind(Enum):
    """What went wrong, coarsely (the message says exactly what)."""

    REACH = "reach"  # a foot out of a leg's reach (IK misses, Theta's contact rows)
    BODY_CLEARANCE = "body clearance"  # the body box near the terrain
    FOOT_ROLL = "foot roll"  # a stance foot rolls into an edge
    LINK_MARGIN = "link margin"  # a thigh or shank nearer the terrain than its path margin
    LINK_CONTACT = "link contact"  # a thigh or shank touches the terrain
    LINK_SWEEP = "link sweep"  # a link passes through the terrain between two samples
    FOOT_SWEEP = "foot sweep"  # a swinging foot passes through the terrain between samples
    TIP = "tip"  # the COM within the path margin of the support triangle's edge
    BALANCE = "balance"  # the friction-cone margin of the static equilibrium (section 6)
    BALANCE_MARGIN = "balance margin"  # Theta2's COM margin inside the support triangle
    FORCES = "forces"  # eq. 5 forces outside their cones or bounds
    TORQUE = "torque"  # a joint torque past its share of the effort
    SWAY = "sway"  # a three-leg stance too soft on the servos
    OTHER = "other"


# Theta problems' constraint groups (ThetaProblem._groups, ``violations``) -> kinds
_GROUP_KINDS = {
    "contact": FailureKind.REACH,
    "reach": FailureKind.REACH,
    "landing": FailureKind.REACH,
    "swing_ready": FailureKind.REACH,
    "clearance": FailureKind.BODY_CLEARANCE,
    "leg_clearance": FailureKind.LINK_MARGIN,
    "landing_clearance": FailureKind.LINK_MARGIN,
    "lift": FailureKind.REACH,
    "lift_branch": FailureKind.REACH,
    "lift_clearance": FailureKind.LINK_MARGIN,
    "forces": FailureKind.FORCES,
    "forces_landing": FailureKind.FORCES,
    "balance_margin": FailureKind.BALANCE_MARGIN,
    "balance_margin_landing": FailureKind.BALANCE_MARGIN,
    "torque": FailureKind.TORQUE,
    "sway": FailureKind.SWAY,
    "sway_psd": FailureKind.SWAY,
}


def kinds_of_groups(groups) -> tuple[FailureKind, ...]:
    """The kinds of violated Theta constraint groups, in their order."""
    return tuple(_GROUP_KINDS.get(g, FailureKind.OTHER) for g in groups)


class Problem(str):
    """A failure message (a ``str``, as people read it) that carries its :class:`FailureKind`."""

    kind: FailureKind

    def __new__(cls, message: str, kind: FailureKind) -> Problem:  # noqa: D102
        obj = super().__new__(cls, message)
        obj.kind = kind
        return obj


def kind_of(why: str) -> FailureKind | None:
    """The kind of a failure message: None for "" (no failure), OTHER for a plain message."""
    if not why:
        return None
    return getattr(why, "kind", FailureKind.OTHER)
