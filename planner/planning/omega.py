"""The search Omega along the trajectory (paper section 7.6, eq. 11).

Omega_1(tau, r_1*..r_4*, i_f) is the set Xi of pairs (Psi, lambda) for which hard
persuasion Theta1(R_tau(lambda), ...) is feasible on the current leaf of S0. Feasibility
along lambda is, in practice, an interval starting at the body's current lambda (the COM
can move forward until a leg runs out of reach or the COM leaves the support), so the
paper searches it by bisection: each probe is one Theta1 solve, warm-started from the
last feasible configuration. :func:`omega` bisects the interval itself;
:func:`farthest_feasible` bisects a list of screened lambdas (the hard planner's, whose
targets are checked without a solve first, :mod:`planner.planning.hard`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planner.body.state import State
from planner.motion.heuristics import reference_directions
from planner.problems.base import ThetaSolution
from planner.problems.theta1 import Theta1


@dataclass
class SearchResult:
    """Xi of eq. 11 (feasible (state, lambda) pairs, sorted by lambda) and the solves made."""

    xi: list[tuple[State, float]] = field(default_factory=list)
    probes: list[tuple[float, bool]] = field(default_factory=list)
    last_failure: ThetaSolution | None = None

    @property
    def best(self) -> tuple[State, float] | None:
        """The feasible pair with the largest lambda (farthest along tau)."""
        return self.xi[-1] if self.xi else None

    @property
    def solves(self) -> int:
        """Number of Theta1 solves the search made."""
        return len(self.probes)


def omega(
    problem: Theta1,
    start: State,
    tau,
    lam_from: float,
    lam_to: float,
    com_offset_W: np.ndarray | None = None,
    tol_m: float = 0.004,
    max_solves: int = 10,
    swing_target_W: np.ndarray | None = None,
    targets=None,
) -> SearchResult:
    """Bisection for the largest lambda in [lam_from, lam_to] where Theta1 is feasible.

    Parameters
    ----------
    problem : Theta1
        Hard persuasion, built for the support pattern in use.
    start : State
        Current configuration on the leaf (footholds fixed); the first warm start.
    tau : Trajectory
        R_tau(lambda) gives the COM targets r_c* = R_tau(lambda) + ``com_offset_W``.
    lam_from, lam_to : float
        Search interval [m of arc length]; ``lam_from`` is taken as already reached.
    com_offset_W : (3,), optional
        Added to R_tau(lambda) (e.g. to follow tau at the current COM height).
    tol_m : float
        Stop when the bracket is shorter than this [m of arc length].
    max_solves : int
        Budget of Theta1 solves.
    swing_target_W : (3,), optional
        Next foothold of the leg that will swing (Theta2's swing-ready constraint).
    targets : callable, optional
        lambda -> (r_c*, u_f, u_n), replacing R_tau(lambda) + ``com_offset_W`` and
        :func:`planner.motion.heuristics.reference_directions` (a body that follows its footholds).

    """
    offset = np.zeros(3) if com_offset_W is None else np.asarray(com_offset_W, float)
    out = SearchResult()
    warm = start

    def probe(lam: float) -> bool:
        nonlocal warm
        if targets is not None:
            rc, u_f, u_n = targets(lam)
        else:
            rc = np.asarray(tau.point(lam), float).reshape(3) + offset
            u_f, u_n = reference_directions(tau, problem.terrain, rc, lam=lam)
        sol = problem.solve(warm, rc, u_f, u_n, swing_target_W)
        out.probes.append((float(lam), sol.feasible))
        if sol.feasible:
            out.xi.append((sol.state, float(lam)))
            warm = sol.state
        else:
            out.last_failure = sol
        return sol.feasible

    lo, hi = float(lam_from), float(lam_to)
    if hi <= lo:
        return out
    if probe(hi):
        return out
    while hi - lo > tol_m and out.solves < max_solves:
        mid = 0.5 * (lo + hi)
        if probe(mid):
            lo = mid
        else:
            hi = mid
    out.xi.sort(key=lambda pair: pair[1])
    return out


def farthest_feasible(
    lams: Sequence[float], solve: Callable[[float], Any], max_solves: int
) -> tuple[Any, float | None]:
    """Omega (eq. 11) over candidate lambdas, farthest first: (solve's result, lambda).

    ``solve(lam)`` returns a result, or None where the problem is infeasible. The
    farthest candidate is solved first; where it fails, feasibility is taken as an
    interval of lambdas up to some point and bisected over the nearer candidates for the
    farthest feasible one, ``max_solves`` solves in all. (None, None) when none is found.
    """
    if not lams or max_solves < 1:
        return None, None
    first = solve(lams[0])
    if first is not None:
        return first, lams[0]
    good: tuple[Any, float | None] = (None, None)
    lo, hi = 1, len(lams) - 1
    for _ in range(max_solves - 1):
        if lo > hi:
            break
        k = (lo + hi) // 2
        got = solve(lams[k])
        if got is not None:
            good, hi = (got, lams[k]), k - 1
        else:
            lo = k + 1
    return good
