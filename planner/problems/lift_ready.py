"""Lift-ready body moves: Theta2 proves the swing leg can lift off (beyond section 7.3).

A landing-ready Theta2 (:mod:`planner.problems.theta2`) proves the swing leg can reach its
next foothold from the body pose; nothing asked that it can leave its present one. With
``ThetaOptions.lift_ready`` three more variables, the swing leg's joints at lift-off
(``theta_lift``), put its sphere ``LIFT_FRACTION_OF_CLEARANCE`` of the default swing
clearance up its foothold's normal, inside the landing's joint bounds, on the same knee
branch (within ``LIFT_JOINT_STEP_RAD`` of the stance joints) and with its links clear: a
leg folded at its knee limit under a low body cannot lift at all, and the swing's first
samples (eq. 6a's liftoff, :func:`planner.motion.interpolate.swing_path`) fail however the
foothold is chosen.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.body.state import State
from planner.motion.interpolate import default_clearance_m
from planner.problems.base import landing_bounds_rad

__all__ = ["LIFT_FRACTION_OF_CLEARANCE", "LIFT_JOINT_STEP_RAD", "LiftReady"]

# lift-ready: the sphere this fraction of the default swing clearance up the normal (the
# liftoff of the half-clearance swing the step tries second: 7.5 mm for LittleDog) ...
LIFT_FRACTION_OF_CLEARANCE = 0.25
LIFT_JOINT_STEP_RAD = 0.35  # ... with joints this near the stance leg's (the same knee branch)


class LiftReady:
    """Theta2's lift-ready rows, their initial guess and their independent check."""

    @property
    def lift_m(self) -> float:
        """How far up its normal the lift-ready swing sphere rises [m]."""
        return LIFT_FRACTION_OF_CLEARANCE * default_clearance_m(self.robot)

    def _constrain_lift(self, pos, R, leg, th_leg, centres, normals) -> None:
        """Lift-ready: ``leg`` can lift its sphere ``lift_m`` up its normal from this pose.

        Variables ``theta_lift``: the leg's joints with the sphere at c + lift_m n (c its
        centre at the move's end, rolled where the feet roll), within the landing's joint
        bounds, within ``LIFT_JOINT_STEP_RAD`` of the stance joints (no knee flip) and with
        thigh and shank clear of the terrain (eq. 6a's liftoff, :mod:`planner.motion.
        interpolate`).
        """
        r = self.robot
        th_lift = self.var("theta_lift", 3, *landing_bounds_rad(r, leg))
        c = ca.reshape(centres, 3, 4)[:, leg]
        n = ca.reshape(normals, 3, 4)[:, leg]
        lift_W = ca.mtimes(R, self.kin.foot_B_ca(leg, th_lift)) + pos
        self.constrain("lift", lift_W - (c + self.lift_m * n))
        d = th_lift - th_leg
        self.constrain("lift_branch", ca.dot(d, d) - LIFT_JOINT_STEP_RAD**2, -np.inf, 0.0)
        self.constrain_leg_links(pos, R, {leg: th_lift}, name="lift_clearance")

    def _lift_guess(self, start: State, p: np.ndarray, R, pos, joints) -> np.ndarray:
        """Lift-off joints: IK of the sphere ``lift_m`` up, same knee, else the stance's."""
        (leg,) = set(range(4)) - set(self.support)
        c = p[self._p_slices["centres_W"]].reshape(4, 3)[leg]
        n = p[self._p_slices["normals_W"]].reshape(4, 3)[leg]
        th = np.asarray(joints, float).reshape(4, 3)[leg]
        knee = self.kin.knee_direction(leg, th)
        up_B = R.T @ (c + self.lift_m * n - pos)
        ik = self.kin.ik_leg(leg, up_B, reference_rad=th, knee=knee)
        return ik.joints_rad if ik.reachable and not ik.knee_flipped else th.copy()

    def _landing_guess(self, start: State, p: np.ndarray) -> np.ndarray:
        """Landing joints: IK of the swing target from the start pose, else theta_nor."""
        (leg,) = set(range(4)) - set(self.support)
        centre_B = start.base_rotation_W.T @ (
            p[self._p_slices["swing_target_W"]] - start.base_position_W
        )
        ik = self.kin.ik_leg(leg, centre_B, reference_rad=start.joints_rad[leg], closest=False)
        return ik.joints_rad if ik.reachable else self.robot.theta_nor[leg].copy()

    def _lift_violations(self, state: State, x, p, centres, leg: int) -> dict[str, float]:
        """The lift-ready rows checked in numpy: the lifted sphere and the knee branch."""
        th = self.x_block(x, "theta_lift")
        up = centres[leg] + self.lift_m * p[self._p_slices["normals_W"]].reshape(4, 3)[leg]
        foot = state.base_rotation_W @ self.kin.foot_B(leg, th) + state.base_position_W
        step = float(np.linalg.norm(th - state.joints_rad[leg]))
        return {
            "lift": float(np.linalg.norm(foot - up)),
            "lift_branch": max(step - LIFT_JOINT_STEP_RAD, 0.0),
        }
