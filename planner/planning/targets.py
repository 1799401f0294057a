"""Where a step goes: the foothold Lambda_t (eq. 13) and the body target Lambda_c (eq. 12).

Section 8.2's heuristics for one step of leg i_f: the body target r_c* = Lambda_c (the
COM shifted toward the other three feet, at the nominal height or following the
footholds), the body's directions u_f, u_n there (section 7.2), the leg's next foothold
Lambda_t taken with the body at r_c* and moved off edges, the other footholds to try when
that one fails, and the stride (long on level ground).

:class:`Targets` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain``, ``mu``, ``settings``, ``kin``, ``check`` and ``_hips_B``,
its :meth:`com_height_m`, and the level-ground test
of :class:`planner.planning.level.LevelGround`.
"""

from __future__ import annotations

import numpy as np

from planner.body.state import State
from planner.motion.footholds import best_and_shortest, foothold_candidates
from planner.motion.gait_queue import CRAWL
from planner.motion.heuristics import (
    body_clearance_height_m,
    frame_from_directions,
    lambda_c,
    lambda_t,
    leg_room,
    reach_height_cap_m,
    reference_directions,
    safe_foothold,
    support_body_target_W,
    two_beat_xy_W,
)
from planner.motion.trajectory import Trajectory
from planner.planning.swing import TARGET_RADIUS_M

__all__ = [
    "ALWAYS_REACH_FRACTION",
    "CANDIDATE_LATERAL_M",
    "CANDIDATE_POOL",
    "OTHER_FOOTHOLDS",
    "TWO_BEAT_SPARE_M",
    "Targets",
]

OTHER_FOOTHOLDS = 8  # footholds tried when the body cannot get ready for Lambda_t's
CANDIDATE_POOL = 40  # candidates scored before the best and the shortest are picked
CANDIDATE_LATERAL_M = 0.05  # other footholds within this of the failed one sideways [m]
# every body target sinks where a leg would be stretched beyond this share of its reach
# (a crawl stance on flat ground reaches 0.94 before a hind leg swings, untouched): with
# three feet up a 10 cm step the footholds' plane put the body 4 cm too high for the fourth
ALWAYS_REACH_FRACTION = 0.95
# com_target "two_beat": the COM stays put, or moves to the deepest point of two supports,
# where it is Theta2's own margin (settings.theta.balance_margin_m) and this much more
# inside, to spare for the pose Theta2 finds near the target [m]
TWO_BEAT_SPARE_M = 0.005


class Targets:
    """The body target, the body's directions, the footholds and the stride of a step."""

    @property
    def balance_margin_m(self) -> float:
        """The COM's margin inside a three-leg support [m]: the one setting, Theta2's."""
        return self.settings.theta.balance_margin_m

    @property
    def two_beat_margin_m(self) -> float:
        """Where the two-beat crawl holds or puts the COM inside two supports [m]."""
        return self.balance_margin_m + TWO_BEAT_SPARE_M

    def stride_m(self) -> float:
        """Stride of Lambda_t [m]: ``settings.step_m`` or 0.35 x the shortest leg reach."""
        st = self.settings
        return st.step_m if st.step_m is not None else 0.35 * float(np.min(self.robot.reach_m))

    def stride_at(self, state: State, leg: int, tau: Trajectory) -> float:
        """The stride of ``leg``'s next step [m]: ``level_stride`` x reach on level ground.

        Elsewhere, and without ``level_stride``, :meth:`stride_m`. Level: the terrain
        (sharp heights, every ``LEVEL_GRID_M``) under the swing's track from the foot to the
        long stride's target, widened by ``LEVEL_WIDTH_M`` each side, and under the stance
        feet lies within ``LEVEL_TOL_M`` of the plane of the four feet, and that plane is
        within ``LEVEL_SLOPE`` of horizontal. A long stride stretches the legs between the
        feet: on steps, stairs and slopes that left stances the servos could not hold on
        three legs (walks on them stalled with 12 cm strides everywhere); on level
        ground it halves the steps of a walk.
        """
        short = self.stride_m()
        if self.settings.level_stride is None:
            return short
        long = self.settings.level_stride * float(np.min(self.robot.reach_m))
        if long <= short:
            return short
        target = self.stride_target(state, leg, tau, long)
        return long if self._level_track(state, leg, target) else short

    def foothold_target(
        self, state: State, leg: int, tau: Trajectory, step_m: float, shrink: float | None = None
    ):
        """Where ``leg`` will go: Lambda_t (eq. 13) moved off edges; returns (point, hazard).

        Lambda_t is taken with the body at r_c* (where the body move will bring it), so
        the foothold matches the stance the leg swings from; :func:`safe_foothold` then
        moves it to the nearest point of the sharp terrain without an edge under the foot
        (beyond the paper), and out of the room the leg's links need before a riser
        (:func:`planner.motion.heuristics.leg_room`), a greedy step's guess at what the
        body's advance over the foot will need; the look-ahead of 8.5
        (``foothold_lookahead``: the recursive planner, soft's retraced steps) checks the
        next body move itself and goes without it. ``hazard`` is "" or why no safe point
        was found nearby.
        """
        target = self.stride_target(state, leg, tau, step_m, shrink)
        u_f, _ = reference_directions(tau, self.terrain, target)
        return safe_foothold(
            self.terrain,
            target,
            u_f,
            self.robot.foot_radius_m,
            self.mu,
            max_shift_m=max(step_m, 0.5 * float(np.min(self.robot.reach_m))),
            not_behind_W=state.feet_W[leg],
            room=None if self.foothold_lookahead else leg_room(self.robot, leg),
        )

    def stride_target(
        self, state: State, leg: int, tau: Trajectory, step_m: float, shrink: float | None = None
    ) -> np.ndarray:
        """Lambda_t (eq. 13) with the body at r_c*: the leg's nominal placement, edges ignored."""
        rc = self.body_target(state, leg, shrink, tau=tau)
        ahead = state.copy()
        ahead.base_position_W = np.array(rc, float)
        return lambda_t(self.robot, self.terrain, ahead, leg, tau, step_m=step_m)

    def other_footholds(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        tried_W,
        shrink: float | None = None,
        centre_W=None,
        max_lateral_m: float = CANDIDATE_LATERAL_M,
        keep=None,
    ) -> list[np.ndarray]:
        """Footholds to try when the body cannot get ready for ``tried_W`` (8.2.2).

        :func:`planner.motion.footholds.foothold_candidates` within ``max_lateral_m`` of
        ``centre_W`` (default ``tried_W``) at the body pose the move aims for (COM at r_c*),
        ``tried_W`` itself and those failing ``keep(point)`` left out, best-scored and
        shortest alternating (:func:`planner.motion.footholds.best_and_shortest`).
        """
        rc = self.body_target(state, leg, shrink, tau=tau)
        u_f, R, body_W = self._body_pose_at(state, leg, tau, rc)
        tried = np.asarray(tried_W, float)
        centre = tried if centre_W is None else np.asarray(centre_W, float).reshape(3)
        found = [
            c
            for c in foothold_candidates(
                self.robot, self.terrain, leg, centre, u_f, body_W, R, self.mu,
                not_behind_W=state.feet_W[leg], max_lateral_m=max_lateral_m,
                limit=CANDIDATE_POOL, accept=keep,
            )
            if np.linalg.norm(c[:2] - tried[:2]) > TARGET_RADIUS_M
        ]  # fmt: skip
        return best_and_shortest(found, state.feet_W[leg], u_f, OTHER_FOOTHOLDS)

    def body_target(
        self,
        state: State,
        leg: int,
        shrink: float | None = None,
        swing_target_W=None,
        tau: Trajectory | None = None,
    ) -> np.ndarray:
        """r_c* = Lambda_c(Psi, i_f) (eq. 12) at the nominal COM height, with ``shrink``.

        With ``follow_support`` the height follows the four footholds
        (:func:`support_body_target_W`), ``leg``'s halfway to its next one
        ``swing_target_W`` when given (the landing-ready body move ends with the leg still
        on its foothold, and from there it must reach the next one), the body facing
        along ``tau`` (not its current heading: a yaw would feed back into the target).
        """
        k = self.settings.shrink if shrink is None else shrink
        feet = self._plane_feet(state, leg, swing_target_W)
        heading = None
        if tau is not None:
            heading = tau.tangent(tau.closest_lambda(state.base_position_W))
        centre = None
        if self.settings.com_target == "two_beat" and self.level_under(state):
            centre = two_beat_xy_W(
                state, leg, self._next_leg(leg), swing_target_W, self.check.com_W(state),
                self.two_beat_margin_m,
            )  # fmt: skip
        rc = lambda_c(
            self.robot, self.terrain, state, leg, self.com_height_m(), k, feet, heading, centre
        )
        if feet is None or tau is None:
            return rc
        return self.sunk_target(state, leg, rc, tau, swing_target_W, heading)

    def sunk_target(self, state: State, leg: int, rc, tau: Trajectory, swing_target_W, heading):
        """``rc`` lowered where a leg would pass ALWAYS_REACH_FRACTION of its reach.

        Not below the body box's clearance over the terrain.
        """
        rc = np.array(rc, float)
        sink = self._reach_sink_m(state, leg, rc, tau, swing_target_W, ALWAYS_REACH_FRACTION)
        if sink < 0.0:
            floor = body_clearance_height_m(self.robot, self.terrain, rc, heading)
            rc[2] = max(rc[2] + sink, min(rc[2], floor))
        return rc

    def _reach_sink_m(
        self, state: State, leg: int, rc, tau: Trajectory, swing_target_W, fraction: float
    ):
        """The body target's drop [m] that keeps every leg within ``fraction`` of reach (<= 0).

        :func:`planner.motion.heuristics.reach_height_cap_m` at the pose the move aims for: the
        three stance legs on their feet, ``leg`` on its next foothold when given.
        """
        _, R, body_W = self._body_pose_at(state, leg, tau, rc, swing_target_W)
        hips_W = self._hips_B @ R.T + body_W
        feet = np.array(state.feet_W, float)
        legs = [i for i in range(4) if i != leg]
        if swing_target_W is not None:
            feet[leg] = np.asarray(swing_target_W, float).reshape(3)
            legs.append(leg)
        centres = feet + self.robot.foot_radius_m * np.asarray(
            self.terrain.normal(feet), float
        ).reshape(4, 3)
        return reach_height_cap_m(self.robot, hips_W, centres, legs, fraction)

    def _body_pose_at(self, state: State, leg: int, tau: Trajectory, rc, swing_target_W=None):
        """(u_f, body rotation, body origin) [world] of the pose with its COM at ``rc``.

        The directions of :meth:`body_directions`, the COM offset of ``state``'s joints.
        """
        u_f, u_n = self.body_directions(tau, state, rc, leg, swing_target_W)
        R = frame_from_directions(u_f, u_n)
        body_W = rc - R @ self.kin.com_B(state.joints_rad, self.settings.theta.whole_body_com)
        return u_f, R, body_W

    def _plane_feet(self, state: State, leg: int, swing_target_W=None):
        """The footholds the body follows, or None (the paper's u_n and height)."""
        if not self.settings.follow_support:
            return None
        feet = np.array(state.feet_W, float)
        if swing_target_W is not None:  # the leg still stands at its foothold: halfway
            feet[leg] = 0.5 * (feet[leg] + np.asarray(swing_target_W, float))
        return feet

    def body_directions(self, tau: Trajectory, state: State, rc, leg: int, swing_target_W=None):
        """(u_f, u_n) of sigma1, sigma2 for the body move at r_c* before ``leg`` swings.

        u_f along tau; u_n the terrain's smoothed normal (section 7.2) or, with
        ``follow_support``, pitched with the footholds (:func:`support_body_target_W`).
        """
        u_f, u_n = reference_directions(tau, self.terrain, rc)
        feet = self._plane_feet(state, leg, swing_target_W)
        if feet is not None:
            _, u_n = support_body_target_W(
                self.robot, self.terrain, feet, rc, self.com_height_m(), u_f, u_n
            )
        return u_f, u_n

    def _next_leg(self, leg: int) -> int:
        """The leg after ``leg`` in ``settings.gait``."""
        gait = list(self.settings.gait or CRAWL)
        return gait[(gait.index(leg) + 1) % len(gait)] if leg in gait else (leg + 1) % 4
