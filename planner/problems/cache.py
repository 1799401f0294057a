"""Theta problems built once per process: a warm planner for notebooks and services.

Building a Theta problem (section 7: its CasADi expressions, their exact derivatives and
IPOPT's setup) costs 0.05-0.3 s, about a tenth of a short plan. A problem depends only on
the robot, the terrain, the options, mu and its own arguments (support pattern, leg), and a
solve starts from its inputs, never from an earlier solve; so the problems of one plan serve
the next plan in the same process whenever these agree. :func:`shared_problem` keys them by
content (:meth:`planner.body.robot_model.Robot.fingerprint`,
:meth:`planner.world.terrain.Terrain.fingerprint`, the options' values), so a robot and a
terrain loaded again by name reuse them too. The store keeps the ``MAX_PROBLEMS`` used last.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

__all__ = ["MAX_PROBLEMS", "clear_problems", "shared_problem", "stored_problems"]

#: problems kept (least recently used dropped); a walk on one terrain uses about a dozen
MAX_PROBLEMS = 64

_STORE: OrderedDict[tuple, Any] = OrderedDict()


def shared_problem(
    cls, robot, terrain, options, mu: float, fingerprints: tuple[str, str] | None = None, **kwargs
):
    """``cls(robot, terrain, options=options, mu=mu, **kwargs)``, built once per process.

    Returns the stored problem when one of ``cls`` was built for a robot and a terrain with
    the same fingerprints and equal options, mu and arguments. ``fingerprints``: the robot's
    and the terrain's, when the caller has them already (taken now otherwise).
    """
    if fingerprints is None:
        fingerprints = (robot.fingerprint(), terrain.fingerprint())
    key = (
        cls.__module__,
        cls.__qualname__,
        *fingerprints,
        repr(options),
        float(mu),
        tuple(sorted((k, repr(v)) for k, v in kwargs.items())),
    )
    problem = _STORE.get(key)
    if problem is None:
        problem = cls(robot, terrain, options=options, mu=mu, **kwargs)
        _STORE[key] = problem
        while len(_STORE) > MAX_PROBLEMS:
            _STORE.popitem(last=False)
    else:
        _STORE.move_to_end(key)
    return problem


def stored_problems() -> int:
    """How many problems the store holds."""
    return len(_STORE)


def clear_problems() -> None:
    """Drop every stored problem (their memory is freed when no planner holds them)."""
    _STORE.clear()
