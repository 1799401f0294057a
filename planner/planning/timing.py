"""A step's samples in time: the time law of its body move and its swing (section 8.3's input).

The paper leaves the timing of its paths open, asking only for quasi-static motion; the
executor (8.3) needs a time per sample. :meth:`Timing.step_samples` gives a step's samples
and times: the body path under :func:`planner.motion.time_law.body_profile` (its
acceleration lowered where the stance cannot carry the inertial force, eq. 4 with
d'Alembert's force; its speed capped near the terrain), the swing under
:func:`planner.motion.time_law.swing_durations_s`, or both overlapping
(:func:`planner.planning.overlap.overlap_step`).

:class:`Timing` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain``, ``mu``, ``settings``, ``check`` and ``torques``, the
body's bottom-face heights (:meth:`planner.planning.path_checks.PathChecks._body_gaps_m`)
and the level-ground test (:class:`planner.planning.level.LevelGround`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from planner.body.stability import PATH_BALANCE_MARGIN_M
from planner.body.state import State
from planner.core.units import GRAVITY_M_S2
from planner.motion.time_law import hip_arm_m, joint_speed_limits_rad_s
from planner.planning.path_checks import BODY_CLEARANCE_M, TORQUE_FRACTION, holding_legs
from planner.planning.step import Step

__all__ = ["Timing"]


class Timing:
    """A step's samples and their times (:meth:`step_samples`), and its keyframes."""

    def step_samples(self, step: Step) -> tuple[list[State], NDArray[np.float64]]:
        """A step's samples and their times [s] from 0 at its start (the executor's too, 8.3).

        The body path, then (a placement) the swing; their shared sample appears once.
        With ``settings.swing_overlap`` the leg lifts before the body move ends where the
        rest of it holds on three legs (:func:`planner.planning.overlap.overlap_step`; found
        once per step, then kept in ``step.overlap``).
        """
        from planner.planning.overlap import overlap_step

        if not step.timed:
            step.overlap = overlap_step(self, step)
            step.timed = True
        if step.overlap is not None:
            return list(step.overlap.states), np.array(step.overlap.times_s)
        states = list(step.body_path)
        times = [0.0] + list(self.body_offsets_s(states))
        if step.ok:
            swing = self.swing_offsets_s(step.swing_path, step.leg)
            states += list(step.swing_path[1:])
            times += list(times[-1] + swing)
        return states, np.array(times[: len(states)])

    def body_offsets_s(self, path: list[State]) -> NDArray[np.float64]:
        """Times [s] of a body path's samples 1.. after its first (:mod:`planner.motion.time_law`).

        The base accelerates at most ``body_accel_m_s2``, less where the stance cannot
        carry the inertial force with ``CARRIED_SHARE`` of its friction-cone margin to
        spare (:meth:`_carried_margin_N`); each interval is checked at its bound in the
        direction the law accelerates it, again if the law changes. Near the sharp terrain
        it goes at most its clearance beyond ``BODY_CLEARANCE_M`` over
        ``BODY_LAG_S`` x sqrt(s) (:func:`planner.motion.time_law.near_terrain_caps`).
        """
        from planner.body.robot_scale import time_scale
        from planner.motion.time_law import (
            BODY_LAG_S,
            body_profile,
            carried_accel_m_s2,
            near_terrain_caps,
        )

        if len(path) < 2:
            return np.zeros(0)
        st = self.settings
        gaps = self._body_gaps_m(path).min(axis=1)
        speed = np.minimum(
            st.body_speed_m_s,
            near_terrain_caps(
                np.minimum(gaps[:-1], gaps[1:]),
                BODY_CLEARANCE_M,
                BODY_LAG_S * time_scale(self.robot),
            ),
        )
        accel = st.body_accel_m_s2
        if st.level_body_accel_m_s2 is not None and self.level_under(path[0]):
            accel = st.level_body_accel_m_s2
        bound = np.full(len(path) - 1, float(accel))
        checked = np.zeros((len(bound), 2))  # magnitude verified, accelerating / braking
        margin = self._carried_margin_N(path)
        while True:
            dt, acc = body_profile(
                np.array([s.base_position_W for s in path]),
                [s.base_rotation_W for s in path],
                np.array([s.joints_rad.ravel() for s in path]),
                speed_m_s=speed,
                accel_m_s2=bound,
                arm_m=hip_arm_m(self.robot),
                vmax_rad_s=joint_speed_limits_rad_s(self.robot),
            )
            todo = [
                (k, int(a < 0.0))
                for k, a in enumerate(acc)
                if abs(a) > checked[k, int(a < 0.0)] * (1 + 1e-9)
            ]
            if not todo:
                return np.cumsum(dt)
            for k, braking in todo:
                sign = -1.0 if braking else 1.0
                bound[k] = carried_accel_m_s2(
                    lambda a, k=k, sign=sign: margin(k, sign * a), bound[k], 0.0
                )
                checked[k, braking] = bound[k]

    def _carried_margin_N(self, path: list[State]):
        """margin(k, a): how far a body path's interval k carries accelerating by ``a``.

        The least, over the interval's two samples, of the friction-cone margin [N] on the
        contact feet with gravity g - a u (u the COM's direction over the interval;
        d'Alembert's inertial force, eq. 4), minus the margin that must remain: the
        path's own (``balance_margin_frac``) or ``CARRIED_SHARE`` of the sample's static
        margin, whichever is more; and the zero-moment point, the COM projected along
        g - a u (:func:`planner.body.stability.tip_margin_m`), inside the support polygon by
        ``CARRIED_SHARE`` of the COM's own tip margin at rest, or by
        ``PATH_BALANCE_MARGIN_M`` where that is more (at most the margin at rest): the
        friction margin stays wide while the far feet unload, and an arrival move braking
        at 1.5 m/s^2 toward an edge 2.9 cm from its COM (the ZMP 6 mm from it) tipped the
        robot over it in MuJoCo, as no swing keeping 21 mm ever did
        (:mod:`planner.body.stability`). The tip part counts in N as the horizontal force that
        would use what is left of it (m g x margin / COM height). And the joint torques of
        the commanded force distribution with gravity g - a u
        (:meth:`planner.body.torques.TorqueCheck.commanded_ratio_map`, on the legs that hold
        the sample: the three of the next swing at a move's end) use at most
        ``CARRIED_SHARE`` of the headroom between the sample's ratio at rest and
        ``TORQUE_FRACTION`` (counted as m g x the ratio). Chosen from MuJoCo runs: a 3.8 cm
        sway braked at 0.5 m/s^2 onto a three-leg stance with a knee at 72 % (88 % while
        braking) saturated the knee and the robot fell; with that move taking twice as
        long it held.
        >= 0: the stance carries the motion.
        """
        from planner.body.stability import tip_margin_m
        from planner.body.statics import GRAVITY_W, static_feasibility
        from planner.motion.time_law import CARRIED_SHARE

        m = self.robot.total_mass_kg
        need = self.settings.balance_margin_frac * m * GRAVITY_M_S2
        g_W = np.asarray(GRAVITY_W, float)
        com = np.array([self.check.com_W(s) for s in path])
        d = np.diff(com, axis=0)
        u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        normals = [self.terrain.normal(s.feet_W) for s in path]

        def raw(j: int, g) -> float:
            s = path[j]
            res = static_feasibility(
                s.feet_W, com[j], m, np.flatnonzero(s.in_contact), self.mu, normals[j], g,
                with_com_margin=False,
            )  # fmt: skip
            return float(res.margin_N) if np.isfinite(res.margin_N) else -np.inf

        floors: dict[int, float] = {}
        tip_floors: dict[int, tuple[float, float]] = {}
        torque_maps: dict[int, tuple[np.ndarray, float]] = {}

        def tip(j: int, g) -> float:
            return tip_margin_m(path[j].feet_W[path[j].in_contact], com[j], g)

        def torque(j: int, g) -> float:
            """Torque headroom [N, as m g x the ratio] of sample j carrying gravity g."""
            if j not in torque_maps:
                s = path[j]
                q = self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
                tmap = self.torques.commanded_ratio_map(
                    q, holding_legs(path, j), normals[j]
                )  # fmt: skip
                still = float(np.abs(tmap @ g_W).max())
                torque_maps[j] = (tmap, still + CARRIED_SHARE * max(TORQUE_FRACTION - still, 0.0))
            tmap, allowed = torque_maps[j]
            return (allowed - float(np.abs(tmap @ g).max())) * m * GRAVITY_M_S2

        def margin(k: int, a: float) -> float:
            out = np.inf
            for j in (k, k + 1):
                if j not in floors:  # the static margin: path_problem's, if it solved it
                    still = path[j].info.get("margin_N")
                    still = raw(j, g_W) if still is None else still
                    floors[j] = max(need, CARRIED_SHARE * still)
                    feet = path[j].feet_W[path[j].in_contact]
                    height = max(float(com[j][2] - feet[:, 2].mean()), 1e-3)
                    tip0 = max(tip(j, g_W), 0.0)
                    floor = min(tip0, max(CARRIED_SHARE * tip0, PATH_BALANCE_MARGIN_M))
                    tip_floors[j] = (floor, m * GRAVITY_M_S2 / height)
                g = g_W - a * u[k]
                floor, per_m = tip_floors[j]
                out = min(out, raw(j, g) - floors[j], (tip(j, g) - floor) * per_m, torque(j, g))
            return out

        return margin

    def swing_offsets_s(self, path: list[State], leg: int) -> NDArray[np.float64]:
        """Times [s] of a swing's samples 1.. after its first (:mod:`planner.motion.time_law`).

        A swing searched in joint space around an edge (``over_edge``) moves its joints at
        ``OVER_EDGE_SPEED_FRACTION`` of their limits.
        """
        from planner.body.robot_scale import time_scale
        from planner.motion.time_law import (
            FOOT_ACCEL_M_S2,
            FOOT_SPEED_M_S,
            JOINT_SPEED_FRACTION,
            LANDING_SPEED_M_S,
            OVER_EDGE_SPEED_FRACTION,
            swing_durations_s,
        )

        if len(path) < 2:
            return np.zeros(0)
        over_edge = any(sample.info.get("over_edge") for sample in path)
        k = time_scale(self.robot)
        dt = swing_durations_s(
            np.array([s.feet_W[leg] for s in path]),
            np.array([s.joints_rad.ravel() for s in path]),
            foot_speed_m_s=FOOT_SPEED_M_S * k,
            landing_speed_m_s=LANDING_SPEED_M_S * k,
            foot_accel_m_s2=FOOT_ACCEL_M_S2,
            least_s=self.settings.swing_time_s,
            vmax_rad_s=joint_speed_limits_rad_s(self.robot),
            fraction=OVER_EDGE_SPEED_FRACTION if over_edge else JOINT_SPEED_FRACTION,
        )
        return np.cumsum(dt)

    def _swing_keyframe(self, path: list[State], leg: int, check) -> State:
        """The mid-swing configuration on S_leg, with its eq. 5 forces (3 stance feet)."""
        from planner.body.statics import equilibrating_forces

        mid = path[len(path) // 2].copy()
        mid.stratum = leg + 1
        mid.support = tuple(i for i in range(4) if i != leg)
        eq = equilibrating_forces(
            mid.feet_W, check.com_W(mid), self.robot.total_mass_kg, mid.support
        )
        mid.forces_W = None if eq.degenerate else eq.forces
        return mid

    @staticmethod
    def _append(samples: list, times: list, path: list, at_s) -> None:
        """Append a path's samples after the first (equal to the last sample) at times ``at_s``."""
        for s, t in zip(path[1:], at_s, strict=True):
            samples.append(s)
            times.append(float(t))
