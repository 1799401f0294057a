"""Whether a sampled path is executable: reach, clearance, balance and torques per sample.

Section 8's keyframes are feasible by construction (the Theta problems), the samples
between them (the leaves' paths, eq. 6b, and the swings) are not: :meth:`path_problem`
checks every sample of a path as the independent plan check does (reach by IK, the body's
bottom face and the leg links over the sharp terrain, the stance feet rolling into an
edge, the static equilibrium of section 6 with a margin, the joint torques) and the motion
between two samples where a joint moves far in one interval.

:class:`PathChecks` is a part of :class:`planner.planning.local.LocalPlanner`; it uses the
planner's ``robot``, ``terrain``, ``mu``, ``settings``, ``kin``, ``check``, ``torques``
and ``_bottom_B`` (the body's bottom-face points).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from planner.body.contact import sphere_penetration_m
from planner.body.links import leg_links
from planner.body.robot import LEG_NAMES
from planner.body.rolling import end_keyframe
from planner.body.stability import PATH_BALANCE_MARGIN_M, support_margin_m
from planner.body.state import State
from planner.body.stiffness import sway_stiffness_of
from planner.body.torques import COMMANDED_TORQUE_FRACTION
from planner.core.failures import FailureKind, Problem
from planner.core.lie import rotation_from_quat
from planner.core.units import GRAVITY_M_S2
from planner.motion.interpolate import BETWEEN_SAMPLES_RAD, BETWEEN_STEP_RAD, between_q

__all__ = [
    "BODY_CLEARANCE_M",
    "FOOT_CUT_TOL_M",
    "MAX_START_TORQUE_FRACTION",
    "START_SLACK_M",
    "TORQUE_FRACTION",
    "PathChecks",
    "holding_legs",
]

BODY_CLEARANCE_M = 0.005  # least height of the body's bottom above the sharp terrain [m]
FOOT_CUT_TOL_M = 1e-4  # a stance foot sphere may overlap the sharp terrain this much (check's)
# joint torque / URDF effort the servos may need to hold a sample (planner.body.torques)
TORQUE_FRACTION = COMMANDED_TORQUE_FRACTION
# feedback (8.3) starts paths at a measured state that may already lack a margin by a
# fraction of a millimetre; a path from it may not lose more than this
START_SLACK_M = 1e-4
MAX_START_TORQUE_FRACTION = 0.9  # ... but never past this (nor below zero clearance):
# without the bounds, each path could lose a little more than the last (a ratchet)


class PathChecks:
    """The checks of a sampled path (:meth:`path_problem`) and the keyframe it ends on."""

    def path_problem(self, path: list[State]) -> str:
        """Why a sampled leaf path is not executable (a typed ``Problem``), or "".

        Keyframes are feasible by construction, the samples between them are not: a leg
        can run out of reach mid-way, the body box can dip onto the sharp terrain (its
        bottom face is checked on a 5 mm grid), a thigh or shank can pass through an edge
        (:meth:`planner.body.links.LegLinks.path_margin`: 1 mm + 1.5 degrees x the distance to
        where the leg is held), and the COM
        moves (the body along eq. 6b, the swing leg's own mass) so that it can leave the
        support, or needs joint torques near the servos' limits (``TORQUE_FRACTION`` of
        the URDF effort in the distribution the feed-forward commands,
        :mod:`planner.body.torques`: a saturated servo cannot track). Every
        sample is checked with IK and the exact friction-cone test
        (:func:`planner.body.statics.static_feasibility`), with a margin of
        ``settings.balance_margin_frac`` x m g; on three legs the COM also stays
        ``planner.body.stability.PATH_BALANCE_MARGIN_M`` inside the support triangle. A start
        that already lacks a clearance or torque margin, or has a leg out of reach (a
        measured state, 8.3: a stretched leg whose foot rolled), is accepted; the path may
        not lose more (the IK miss may only shrink until the leg is back in reach).
        """
        why = self._reach_problem(path) or self._body_problem(path) or self._rolled_problem(path)
        if why:
            return why
        links = leg_links(self.robot)
        qs = [
            self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad) for s in path
        ]
        why, bares = self._links_problem(path, qs, links)
        why = why or self._between_samples(path, qs, links, bares)
        if why:
            return why
        coms = [self.check.com_W(s) for s in path]  # Pinocchio, once per sample
        why = self._tip_problem(path, coms)
        if why:
            return why
        # every sample's feet in one terrain pass, for the balance and the torques
        normals = np.asarray(self.terrain.normal(np.array([s.feet_W for s in path])), float)
        return self._balance_problem(path, coms, normals) or self._torque_problem(path, qs, normals)

    def _reach_problem(self, path: list[State]) -> str:
        """Why a sample leaves a leg's reach (its IK misses), or "".

        A start out of reach (a measured state, 8.3) is accepted; after it the miss may
        only shrink until the leg is back in reach.
        """
        miss = 0.0  # a start out of reach (a measured state, 8.3): no farther out after it
        for k, s in enumerate(path):
            if not s.info.get("ik_ok", True):
                err = float(s.info.get("ik_error_m", np.inf))
                if k == 0 or err <= miss + 1e-6:
                    miss = err if k == 0 else min(miss, err)
                    continue
                legs = ", ".join(LEG_NAMES[i] for i in s.info.get("unreachable_legs", []))
                why = f"sample {k} of the path leaves the reach of {legs or 'a leg'}"
                return Problem(why, FailureKind.REACH)
            miss = 0.0
        return ""

    def _body_problem(self, path: list[State]) -> str:
        """Why the body's bottom face comes within ``BODY_CLEARANCE_M`` of the terrain, or ""."""
        gaps = self._body_gaps_m(path)
        # a measured start may lack the margin: the path must not lose more
        body_floor = max(min(BODY_CLEARANCE_M, float(gaps[0].min()) - START_SLACK_M), 0.0)
        for k, gap in enumerate(gaps):
            if float(gap.min()) < body_floor:
                return Problem(
                    f"the body passes {float(gap.min()) * 1000:.1f} mm above the terrain at "
                    f"sample {k} of the path (less than {BODY_CLEARANCE_M * 1000:.0f} mm)",
                    FailureKind.BODY_CLEARANCE,
                )
        return ""

    def _rolled_problem(self, path: list[State]) -> str:
        """Why a stance foot ends the path rolled into an edge of the terrain, or ""."""
        # stance feet roll as their shanks turn: at the path's end none rolled into an
        # edge (a riser); a measured start may already touch one, the path no deeper
        end, start = path[-1], path[0]
        stance = np.flatnonzero(end.in_contact)
        if len(stance):
            cut = self._foot_cut_m(end, stance)
            allowed = np.maximum(self._foot_cut_m(start, stance), 0.0) + FOOT_CUT_TOL_M
            j = int(np.argmax(cut - allowed))
            if cut[j] > allowed[j]:
                return Problem(
                    f"the {LEG_NAMES[stance[j]]} foot rolls {cut[j] * 1000:.1f} mm into an edge "
                    "of the terrain on the path",
                    FailureKind.FOOT_ROLL,
                )
        return ""

    def _links_problem(self, path: list[State], qs: list, links) -> tuple[str, list]:
        """(why a leg link comes too near the terrain at a sample or "", the links' bounds).

        The bounds: (N, C) clearances of the links without their path margin, for
        :meth:`_between_samples`.
        """
        swings = [[i for i in range(4) if not s.in_contact[i]] for s in path]
        shorts, bares = links.path_margins(self.terrain, qs, swings, scales=(1.0, 0.0))
        # as for the body: not below what the start already has; nor touching deeper
        floor = np.minimum(shorts[0] - START_SLACK_M, 0.0)
        bare_floor = np.minimum(bares[0] - START_SLACK_M, 0.0)
        for k, (short, bare) in enumerate(zip(shorts, bares, strict=True)):
            c = int(np.argmin(short - floor))
            if short[c] < floor[c]:
                return Problem(
                    f"the {links.describe(c)} comes {-short[c] * 1000:.1f} mm nearer the terrain "
                    f"than its path margin at sample {k} of the path",
                    FailureKind.LINK_MARGIN,
                ), bares
            if short.min() < 0.0:  # inside the margin, as the measured start: not touching
                c = int(np.argmin(bare - bare_floor))
                if bare[c] < bare_floor[c]:
                    why = f"the {links.describe(c)} touches the terrain at sample {k} of the path"
                    return Problem(why, FailureKind.LINK_CONTACT), bares
        return "", bares

    def _tip_problem(self, path: list[State], coms: list) -> str:
        """Why the COM of a three-leg sample is within PATH_BALANCE_MARGIN_M of tipping, or ""."""
        for k, s in enumerate(path):
            sup = holding_legs(path, k)
            if len(sup) != 3:
                continue
            tip = support_margin_m(s.feet_W[sup], coms[k])
            if tip < PATH_BALANCE_MARGIN_M:
                return Problem(
                    f"the COM is {tip * 1000:.1f} mm inside the support triangle at sample "
                    f"{k} of the path (< {PATH_BALANCE_MARGIN_M * 1000:.0f} mm: a tip-over "
                    "risk)",
                    FailureKind.TIP,
                )
        return ""

    def _balance_problem(self, path: list[State], coms: list, normals: np.ndarray) -> str:
        """Why an inner sample lacks the friction-cone margin (section 6), or "".

        Records each sample's margin in ``info["margin_N"]`` (the time law's floor).
        """
        from planner.body.statics import static_feasibility

        mg = self.robot.total_mass_kg * GRAVITY_M_S2
        need = self.settings.balance_margin_frac * mg
        for k, s in enumerate(path[1:-1], start=1):
            sup = np.flatnonzero(s.in_contact)
            res = static_feasibility(
                s.feet_W,
                coms[k],
                self.robot.total_mass_kg,
                sup,
                self.mu,
                normals[k],
                with_com_margin=False,
            )
            s.info["margin_N"] = float(res.margin_N)  # the time law's floor (body_offsets_s)
            if not res.margin_N >= need:  # nan (solver failure) fails too
                return Problem(
                    f"balance lost at sample {k} of the path (friction-cone margin "
                    f"{res.margin_N:.2f} N < {need:.2f} N): the COM leaves the support",
                    FailureKind.BALANCE,
                )
        return ""

    def _torque_problem(self, path: list[State], qs: list, normals: np.ndarray) -> str:
        """Why a sample needs joint torques past ``TORQUE_FRACTION``, or the end sways, or ""."""
        ceiling = TORQUE_FRACTION
        for k, (s, q) in enumerate(zip(path, qs, strict=True)):
            sup = holding_legs(path, k)
            tq = self.torques.solve(q, sup, self.mu, normals[k], least_squares=True)
            if k == 0 and np.isfinite(tq.ratio):  # a measured start: no more than it needs
                ceiling = max(TORQUE_FRACTION, min(tq.ratio, MAX_START_TORQUE_FRACTION))
            if not tq.ratio <= ceiling:
                j = max(tq.worst_joint, 0)
                return Problem(
                    f"joint {self.robot.joint_names[j]} needs {100 * tq.ratio:.0f} % of its "
                    f"effort limit at sample {k} of the path (more than "
                    f"{100 * TORQUE_FRACTION:.0f} %)",
                    FailureKind.TORQUE,
                )
            bound = self.settings.theta.sway_stiffness
            if k == len(path) - 1 and len(sup) == 3 and bound is not None:
                # the three-leg stance the path ends in holds on the servos (Theta2's
                # bound, on the rolled feet the path ends on)
                sway = sway_stiffness_of(self.robot)
                have = sway.stance(
                    s.base_position_W, s.base_rotation_W, s.joints_rad, sup,
                    np.nan_to_num(tq.torques_nm),
                ).least  # fmt: skip
                need = sway.bound_n_per_m(bound)
                if not have >= need:
                    return Problem(
                        f"the three-leg stance at the end of the path sways: stiffness "
                        f"{have:.0f} N/m on the servos (< {need:.0f} N/m; -inf: a singular "
                        "support leg)",
                        FailureKind.SWAY,
                    )
        return ""

    def _body_gaps_m(self, path: list[State]) -> NDArray[np.float64]:
        """(N, K) heights [m] of the body's bottom-face points over the sharp terrain."""
        pts_B = self._bottom_B
        pts = np.array([pts_B @ s.base_rotation_W.T + s.base_position_W for s in path])
        return pts[..., 2] - np.asarray(self.terrain.height_sharp(pts[..., 0], pts[..., 1]))

    def _foot_cut_m(self, state: State, legs) -> np.ndarray:
        """How far the sharp terrain cuts into ``legs``' foot spheres at ``state`` [m]."""
        R, p = state.base_rotation_W, state.base_position_W
        centres = np.array([R @ self.kin.foot_B(i, state.joints_rad[i]) + p for i in legs])
        return sphere_penetration_m(self.terrain, centres, self.robot.foot_radius_m)

    def _between_samples(self, path: list[State], qs: list, links, bares: list) -> str:
        """Why the motion between two samples passes a leg link through the terrain, or "".

        The executor interpolates the joints linearly between samples; where a joint moves
        more than ``BETWEEN_SAMPLES_RAD`` in one interval (a knee flipping at lift-off) the
        leg sweeps unchecked: its links are checked every ``BETWEEN_STEP_RAD`` there, and
        may come no nearer the terrain than at the interval's two ends or 0. In MuJoCo a
        front knee flipped 144 degrees between two clear samples put the shank 16 mm
        through a stone between them, and the robot tipped over.
        ``bares`` (N, C): the links' clearance bounds at the samples (path_problem's); the
        configurations between samples are measured in one terrain query per set of legs
        swept.
        """
        sweeps = []  # (k, legs swept, swing legs, configurations between k and k + 1)
        for k in range(len(path) - 1):
            a, b = path[k], path[k + 1]
            leg_jump = np.max(np.abs(b.joints_rad - a.joints_rad), axis=1)  # (4,) [rad]
            jump = float(leg_jump.max())
            if jump <= BETWEEN_SAMPLES_RAD:
                continue
            swing = [i for i in range(4) if not (a.in_contact[i] and b.in_contact[i])]
            # a leg moving less than one sweep step is within it of its ends (a stance leg
            # beside a swing does not move at all): only the others are swept
            legs = tuple(int(i) for i in np.flatnonzero(leg_jump > BETWEEN_STEP_RAD))
            m = int(np.ceil(jump / BETWEEN_STEP_RAD))
            inner = [between_q(qs[k], qs[k + 1], u) for u in np.arange(1, m) / m]
            sweeps.append((k, legs, swing, inner, leg_jump))
        measured: dict[int, np.ndarray] = {}
        for legs in {legs for _, legs, _, _, _ in sweeps}:
            group = [sw for sw in sweeps if sw[1] == legs]
            qs_all = [q for sw in group for q in sw[3]]
            swings = [sw[2] for sw in group for _ in sw[3]]
            out = links.path_margins(self.terrain, qs_all, swings, scales=(0.0,), legs=legs)[0]
            at = 0
            for sw in group:
                measured[sw[0]] = out[at : at + len(sw[3])]
                at += len(sw[3])
        for k, _, _, _, leg_jump in sweeps:
            floor = np.minimum(np.minimum(bares[k], bares[k + 1]), 0.0) - START_SLACK_M
            for bare in measured[k]:
                c = int(np.argmin(bare - floor))
                if bare[c] < floor[c]:
                    return Problem(
                        f"the {links.describe(c)} passes {-bare[c] * 1000:.1f} mm through the "
                        f"terrain between samples {k} and {k + 1} of the path ("
                        f"{_moves(leg_jump, links.capsules[c].leg)})",
                        FailureKind.LINK_SWEEP,
                    )
        return self._feet_between_samples(path, sweeps)

    def _feet_between_samples(self, path: list[State], sweeps: list) -> str:
        """Why a swinging foot's sphere passes through the terrain between samples, or "".

        The feet of :meth:`_between_samples`' sweeps (legs not down at both ends), at the
        same configurations: the sphere may cut the sharp terrain no deeper than at the
        interval's ends or ``FOOT_CUT_TOL_M`` (the check's). A swing out of a 12 cm trench
        flipped a front knee 140 degrees between two samples 15 and 31 mm clear; the
        straight-line joints between them put the foot 7 mm into the trench's floor, and
        the open-loop walk fell in MuJoCo (the links passed).
        """
        rho = self.robot.foot_radius_m
        for k, legs, swing, inner, leg_jump in sweeps:
            feet = [i for i in swing if i in legs]
            if not feet or not inner:
                continue
            centres = []
            for q in inner:
                R = rotation_from_quat(np.asarray(q[3:7], float))
                joints = self.robot.joints_from_q(q)
                centres += [R @ self.kin.foot_B(i, joints[i]) + q[:3] for i in feet]
            cut = sphere_penetration_m(self.terrain, np.array(centres), rho)
            worst = cut.reshape(len(inner), len(feet)).max(axis=0)
            ends = np.maximum(self._foot_cut_m(path[k], feet), self._foot_cut_m(path[k + 1], feet))
            allowed = np.maximum(ends, 0.0) + FOOT_CUT_TOL_M
            j = int(np.argmax(worst - allowed))
            if worst[j] > allowed[j]:
                return Problem(
                    f"the {LEG_NAMES[feet[j]]} foot passes {worst[j] * 1000:.1f} mm through the "
                    f"terrain between samples {k} and {k + 1} of the path ("
                    f"{_moves(leg_jump, feet[j])})",
                    FailureKind.FOOT_SWEEP,
                )
        return ""

    def path_end(self, path: list[State], support: tuple[int, ...]) -> State:
        """The last sample of a path as the keyframe it ends on (:func:`end_keyframe`).

        The stance feet roll along the path (:mod:`planner.body.rolling`), so the path ends with
        the keyframe's pose on feet a few millimetres from the Theta solution's; its joints
        are the path's (IK onto the rolled feet) and its forces are solved again for them.
        """
        end = end_keyframe(self.robot, path, support, self.check.com_W(path[-1]))
        path[-1] = end
        return end


def holding_legs(path: list[State], k: int) -> np.ndarray:
    """The legs that carry sample ``k`` of a path: its contacts.

    At a body move's end (four feet down, a three-leg support) the three that will hold it
    when the fourth lifts: balance and torque are judged on them.
    """
    s = path[k]
    sup = np.flatnonzero(s.in_contact)
    if len(sup) == 4 and k == len(path) - 1 and len(s.support) == 3:
        return np.asarray(s.support)
    return sup


def _moves(leg_jump, leg: int) -> str:
    """What moved between two samples, for a sweep's message.

    ``leg``'s largest joint change, and that of the leg that moved most where it is
    another one (``leg_jump``: (4,) [rad]).
    """
    own = f"its joints move {float(leg_jump[leg]):.2f} rad there"
    most = int(np.argmax(leg_jump))
    if most == int(leg):
        return own
    return f"{own}, {LEG_NAMES[most]}'s {float(leg_jump[most]):.2f} rad"
