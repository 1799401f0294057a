"""A landing next to a tall edge: which knee branch the leg lands on, and whether it blocks.

Beyond the paper (section 8.5's step places the foot with Theta3 and moves on): next to a
barrier or a tall riser, a leg that lands clear can still meet the edge with its thigh or
shank as the next body moves carry the body over the foot. :meth:`_other_knee_landing`
lands it on its other knee branch where that keeps its links clearer; :meth:`blocks_passage`
refuses a landing after which the body cannot pass over the foot at all. Both judge only
feet within half a leg's reach of terrain ``KNEE_CHOICE_EDGE_M`` higher.

:class:`Landing` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain`` and ``kin``, and its :meth:`stride_m`.
"""

from __future__ import annotations

import numpy as np

from planner.body.links import leg_links
from planner.body.state import State
from planner.motion.heuristics import nominal_height_m

__all__ = [
    "KNEE_CHOICE_CLEARANCE_M",
    "KNEE_CHOICE_EDGE_M",
    "KNEE_CHOICE_FOOT_ZONE_M",
    "KNEE_CHOICE_GAIN_M",
    "KNEE_CHOICE_LOOKAHEAD",
    "PASSAGE_CLEARANCE_M",
    "PASSAGE_RAISES_M",
    "PASSAGE_STRIDES",
    "Landing",
]

KNEE_CHOICE_CLEARANCE_M = 0.015  # a landing whose links are nearer an edge than this ...
KNEE_CHOICE_GAIN_M = 0.01  # ... takes the other knee branch if it is this much clearer
KNEE_CHOICE_EDGE_M = 0.06  # ... next to an edge this much higher than the foothold
KNEE_CHOICE_LOOKAHEAD = 0.5  # fraction of a stride the body is moved ahead to judge it
KNEE_CHOICE_FOOT_ZONE_M = 0.03  # (link points this near the foot centre do not count)
# a landing next to a tall edge must let the body pass over the foot (foothold_passage):
PASSAGE_STRIDES = (0.5, 1.0)  # the body this many strides further along ...
PASSAGE_RAISES_M = (0.0, 0.01, 0.02)  # ... at its nominal height or this much higher ...
PASSAGE_CLEARANCE_M = 0.005  # ... keeps the leg's links (away from the foot) this clear


class Landing:
    """The knee branch of a landing next to a tall edge, and landings that block the body."""

    def _other_knee_landing(self, touch: State, leg: int, want: int | None = None) -> State | None:
        """``touch`` with ``leg`` on its other knee branch, where that clears an edge better.

        Beyond the paper: a leg that lands next to a tall edge with its knee over it (a
        hind leg before a barrier, whose knee points forward) is clear at touch-down, but
        the body moves that follow lower the knee onto the edge. Both branches are judged
        with the body ``KNEE_CHOICE_LOOKAHEAD`` of a stride further along (where the next
        moves take it; a whole stride leaves the reach of a leg at the back), also lowered
        to the nominal height over the ground (a raised body comes down), by the least
        clearance of the leg's links away from the foot (where the shank always comes
        near the ground): the other branch is taken when the leg's own one comes within
        ``KNEE_CHOICE_CLEARANCE_M`` there and the other is ``KNEE_CHOICE_GAIN_M`` clearer.
        The swing then changes branch in the air (:func:`joint_space_swing`). Only next
        to a tall edge (terrain within half the leg's reach ``KNEE_CHOICE_EDGE_M`` above
        the foothold: a barrier, a tall riser): on stepping stones it flipped knees over
        their few centimetres of height and the open-loop walk fell.

        ``want`` (+1/-1): the branch to land on, chosen before (the precomputed plan's, 8.3:
        from a state a few millimetres off, the choice made anew can land the leg on the
        other branch, where the plan's next steps find no body move); None when
        ``touch`` is on it or the leg cannot reach its foot on it.
        """
        if want is not None:
            th = touch.joints_rad[leg]
            if self.kin.knee_direction(leg, th) == int(want):
                return None
            ik = self.kin.ik_leg(leg, self.kin.foot_B(leg, th), reference_rad=th, knee=int(want))
            if not ik.reachable or ik.knee_flipped:
                return None
            return _with_leg_joints(touch, leg, ik.joints_rad)
        R = touch.base_rotation_W
        th = touch.joints_rad[leg]
        centre = R @ self.kin.foot_B(leg, th) + touch.base_position_W
        ahead = R[:, 0].copy()
        ahead[2] = 0.0
        ahead *= KNEE_CHOICE_LOOKAHEAD * self.stride_m() / max(float(np.linalg.norm(ahead)), 1e-9)
        moved = touch.copy()
        moved.base_position_W = touch.base_position_W + ahead
        lowered = moved.copy()  # ... and at the nominal height over the ground there
        lowered.base_position_W[2] = min(
            moved.base_position_W[2],
            float(self.terrain.height(*moved.base_position_W[:2])) + nominal_height_m(self.robot),
        )

        def clearance(knee: int) -> tuple[float, np.ndarray | None]:
            """Least far clearance of the leg on branch ``knee`` at the three body poses."""
            out, joints = np.inf, None
            for s in (touch, moved, lowered):
                got = self._far_link_clearance(s, leg, centre, th, knee)
                if got is None:
                    if s is touch:
                        return -np.inf, None
                    continue  # out of reach there: the body will not go there
                joints = got[1] if joints is None else joints
                out = min(out, got[0])
            return out, joints

        if not self._next_to_tall_edge(touch.feet_W[leg], leg):
            return None
        own = self.kin.knee_direction(leg, th)
        have, _ = clearance(own)
        if have >= KNEE_CHOICE_CLEARANCE_M:
            return None
        better, joints = clearance(-own)
        if joints is None or better < have + KNEE_CHOICE_GAIN_M:
            return None
        return _with_leg_joints(touch, leg, joints)

    def blocks_passage(self, touch: State, leg: int) -> bool:
        """Whether ``leg``, landed as in ``touch`` next to a tall edge, stops the body passing.

        Beyond the paper: a hind foot a few centimetres before a barrier, its knee pointing
        ahead, lands clear, but the body cannot then move over it (the shank sweeps into
        the barrier), and its other knee branch is out of its joint limits there: the walk
        is stuck. The leg is judged on its
        branch with the body ``PASSAGE_STRIDES`` of a stride further along, at its nominal
        height over the ground or up to ``PASSAGE_RAISES_M`` higher: blocked where at some
        such distance the leg reaches its foot and no height keeps its links (away from
        the foot) ``PASSAGE_CLEARANCE_M`` clear. Only next to a tall edge (as
        :meth:`_other_knee_landing`).
        """
        if not self._next_to_tall_edge(touch.feet_W[leg], leg):
            return False
        R = touch.base_rotation_W
        th = touch.joints_rad[leg]
        knee = self.kin.knee_direction(leg, th)
        centre = R @ self.kin.foot_B(leg, th) + touch.base_position_W
        ahead = R[:, 0].copy()
        ahead[2] = 0.0
        ahead /= max(float(np.linalg.norm(ahead)), 1e-9)
        for strides in PASSAGE_STRIDES:
            base = touch.base_position_W + ahead * strides * self.stride_m()
            ground = float(self.terrain.height(*base[:2])) + nominal_height_m(self.robot)
            reached = False
            for dz in PASSAGE_RAISES_M:
                moved = touch.copy()
                moved.base_position_W = np.array([base[0], base[1], ground + dz])
                got = self._far_link_clearance(moved, leg, centre, th, knee)
                if got is None:
                    continue
                reached = True
                if got[0] >= PASSAGE_CLEARANCE_M:
                    break
            else:
                if reached:
                    return True
        return False

    def _far_link_clearance(self, s: State, leg: int, centre_W, th, knee: int):
        """(clearance [m], joints) of ``leg``'s links away from its foot, or None.

        At body pose ``s`` with the foot centre at ``centre_W`` on knee branch ``knee``
        (``th``: the IK's reference); None where the leg cannot reach it so. The least
        clearance of the leg's link points farther than ``KNEE_CHOICE_FOOT_ZONE_M`` from
        the foot (near it the shank always comes close to the ground); inf if there are none.
        """
        R = s.base_rotation_W
        ik = self.kin.ik_leg(leg, R.T @ (centre_W - s.base_position_W), reference_rad=th, knee=knee)
        if not ik.reachable or ik.knee_flipped:
            return None
        links = leg_links(self.robot)
        j = s.joints_rad.copy()
        j[leg] = ik.joints_rad
        q = self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, j)
        gap, pts = links.point_clearances(self.terrain, q)
        mine = np.array([links.capsules[c].leg == leg for c in links.owner])
        far = mine & (np.linalg.norm(pts - centre_W, axis=1) >= KNEE_CHOICE_FOOT_ZONE_M)
        return (float(gap[far].min()) if far.any() else np.inf), ik.joints_rad

    def _next_to_tall_edge(self, foot_W, leg: int) -> bool:
        """Terrain within half ``leg``'s reach ``KNEE_CHOICE_EDGE_M`` above ``foot_W``."""
        foot = np.asarray(foot_W, float).reshape(3)
        r = 0.5 * float(self.robot.reach_m[leg])
        u = np.linspace(-r, r, 15)
        X, Y = np.meshgrid(foot[0] + u, foot[1] + u)
        near = np.hypot(X - foot[0], Y - foot[1]) <= r
        H = np.asarray(self.terrain.height_sharp(X[near], Y[near]), float)
        return float(H.max()) >= float(foot[2]) + KNEE_CHOICE_EDGE_M


def _with_leg_joints(state: State, leg: int, joints_rad) -> State:
    """A copy of ``state`` with ``leg``'s joints replaced (the same foot, another branch)."""
    out = state.copy()
    out.joints_rad = state.joints_rad.copy()
    out.joints_rad[leg] = joints_rad
    return out
