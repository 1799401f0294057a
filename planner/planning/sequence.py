"""Footholds from the contact-sequence search, realised step by step (beyond section 8.2).

With ``settings.footholds`` "search" a step's first foothold comes from the contact-sequence
search (:class:`planner.motion.contact_search.ContactSearch`): Lambda_t's (eq. 13) where
every later step of the gait cycle still has a certified foothold after it, else the
first of a certified sequence (the one found at the step before, where the walk followed
it). The search runs at every step, from the stance the walk is in. The step's body move
aims for Lambda_c's target and, where that step fails, for its certificate's COM
(:meth:`planner.planning.stepping.Stepping.step`); a step the Theta problems cannot realise
is remembered (:meth:`~planner.motion.contact_search.ContactSearch.mark_failed`) and the
next search repairs from there.

:class:`ContactSequence` is a part of :class:`planner.planning.local.LocalPlanner`; it uses
the planner's ``robot``, ``terrain``, ``mu``, ``settings``, ``extra_stats``,
``balance_margin_m`` and :meth:`_next_leg`.
"""

from __future__ import annotations

import numpy as np

from planner.body.state import State
from planner.motion.contact_search import ContactSearch, SearchSettings
from planner.motion.trajectory import Trajectory

__all__ = ["FLOOR_SPAN_M", "ContactSequence"]

FLOOR_SPAN_M = 0.03  # the body's footprint, widened by this, bounds its least height


class ContactSequence:
    """The contact-sequence search inside the local planner (module docstring)."""

    def searched_foothold(
        self, state: State, leg: int, tau: Trajectory, step_m: float, proposal_W
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """(foothold, COM) of the first step of a certified sequence from ``state``, or None.

        ``proposal_W`` (Lambda_t's) is tried first and kept when every later step of the
        cycle still has a certified foothold; the COM is where the step's certificate holds
        the body (a body-move target the step may fall back on). None: the search is off
        or found nothing.
        """
        if self.settings.footholds != "search":
            return None
        steps = self._search_cycle(state, leg, tau, step_m, proposal_W, only_first=False)
        if not steps:
            return None
        _, foothold, cert = steps[0]
        return np.array(foothold), np.array(cert.com_W)

    def certified_first(self, state: State, leg: int, tau: Trajectory, step_m: float, footholds):
        """``footholds`` (the other footholds a step tries, 8.2.2), certified ones first.

        A foothold that starts a sequence certified a whole gait cycle ahead
        (:meth:`certified_ahead`) is tried before those that do not; these stay, last: the
        certificates are conservative (no body tilt of its own, the body's floor over the
        whole footprint), and a barrier is crossed on steps they refuse. Unchanged with
        the search off.
        """
        if self.settings.footholds != "search":
            return list(footholds)
        ok = [self.certified_ahead(state, leg, tau, step_m, c) for c in footholds]
        return [c for c, y in zip(footholds, ok, strict=True) if y] + [
            c for c, y in zip(footholds, ok, strict=True) if not y
        ]

    def certified_ahead(self, state: State, leg: int, tau: Trajectory, step_m: float, c) -> bool:
        """Whether ``leg`` to ``c`` starts a sequence certified a whole gait cycle ahead."""
        steps = self._search_cycle(state, leg, tau, step_m, c, only_first=True)
        return len(steps) == self._contact_search(tau).settings.horizon

    def _search_cycle(self, state: State, leg: int, tau: Trajectory, step_m, first_W, only_first):
        """The search over the gait cycle from ``leg`` (``horizon`` legs), recorded in stats."""
        search = self._contact_search(tau)
        legs = [leg]
        while len(legs) < search.settings.horizon:
            legs.append(self._next_leg(legs[-1]))
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        steps = search.search(
            feet, state.base_position_W, legs, step_m, first_W=first_W, only_first=only_first
        )
        self.extra_stats["contact_search"] = dict(search.stats)  # the plan's record
        return steps

    def mark_unrealised(self, state: State, leg: int, foothold_W) -> None:
        """The Theta problems could not move ``leg`` to ``foothold_W``: the search learns it."""
        search = getattr(self, "_contact_searcher", None)
        if search is not None:
            search.mark_failed(np.asarray(state.feet_W, float), leg, np.asarray(foothold_W))
            self.extra_stats["contact_search"] = dict(search.stats)

    def mark_realised(self) -> None:
        """The Theta problems made the searched step: counted in the search's stats."""
        search = getattr(self, "_contact_searcher", None)
        if search is not None:
            search.mark_realised()
            self.extra_stats["contact_search"] = dict(search.stats)

    def _contact_search(self, tau: Trajectory) -> ContactSearch:
        search = getattr(self, "_contact_searcher", None)
        if search is None or getattr(self, "_search_tau", None) is not tau:
            box_lo_z = float(self.robot.body_box_B[0][2])
            half = 0.5 * (np.asarray(self.robot.body_box_B[1]) - self.robot.body_box_B[0])
            span = half[:2] + FLOOR_SPAN_M
            clearance = self.settings.theta.clearance_m

            def forward(p):  # u_f of reference_directions (7.2), without its normal
                lam = tau.closest_lambda(np.asarray(p, float).reshape(3))
                return np.asarray(tau.tangent(lam), float).reshape(3)

            def z_floor(feet_W):
                c = np.asarray(feet_W, float).mean(axis=0)
                xs = np.linspace(c[0] - span[0], c[0] + span[0], 13)
                ys = np.linspace(c[1] - span[1], c[1] + span[1], 5)
                X, Y = np.meshgrid(xs, ys)
                return float(np.max(self.terrain.height_sharp(X, Y))) + clearance - box_lo_z

            settings = SearchSettings(balance_margin_m=self.balance_margin_m, clearance_m=clearance)
            search = ContactSearch(self.robot, self.terrain, self.mu, forward, z_floor, settings)
            self._contact_searcher, self._search_tau = search, tau
        return search
