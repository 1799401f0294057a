"""Contact-sequence search: footholds chosen a gait cycle ahead, with certificates.

Beyond the paper: section 8.2's queue takes one foothold at a time (Lambda_t, eq. 13) and
learns that a leg was left behind only when no body move reaches it. Here the next
``horizon`` steps of the gait (a crawl cycle and the first leg's next step) are searched
together: a depth-first search over stances (the four footholds), the step's own proposal
first, then the next foothold of the sequence found at the step before (where the walk
followed it), then each leg's candidates best first
(:func:`planner.motion.footholds.foothold_candidates`: reachable, safe under the sharp
terrain, scored by progress, posture and slope). An edge (one leg moved) is kept only
with a *certificate*: a body pose, its orientation from the feet's plane (or a share of
its tilt, ``TILTS``) and the guide path's direction, at which

- the COM is at least the balance margin inside the triangle of the three feet that stay
  (the three-foot support margin of Theta2, 7.3), the legs' own mass counted,
- every foot centre of the stance is within ``STANCE_REACH_SHARE`` of its leg's reach of
  the hip, and the swing leg's hip within ``SWING_REACH_SHARE`` of its reach of the new
  foothold (the workspace zeta_i of 4.4, with Theta2's own fractions),
- the body's bottom face is ``clearance_m`` above the sharp terrain under the stance,
- the legs reach their feet within their joint limits, their thigh and shank keep the
  planner's path margin from the terrain, the swing leg can lift its foot and set it down
  with its links clear, and no support joint needs more than the commanded share of its
  effort (:func:`leg_check`).

The first three are convex: a second-order cone program (Clarabel) finds the position of
largest margin (its height near the nominal one); the last are checked there and at
positions towards the ends of the feasible ones along x_B. The certificates are held no
looser than the Theta problems they certify (a looser one passes steps the problems
cannot make, and the walk stalls where the search promised a way). The Theta problems
(the paper's continuous layer) then realise the steps, a step's body move aiming for its
certificate's COM where Lambda_c's target fails; an edge they cannot realise is
remembered (:meth:`ContactSearch.mark_failed`) and pruned from later searches, which
repair from the stance the walk is in.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from planner.body.kinematics import hip_point_B, kinematics_of, robot_cached
from planner.body.links import leg_links
from planner.body.margins import COMMANDED_TORQUE_FRACTION
from planner.body.stability import support_margin_m
from planner.body.state import State
from planner.body.torques import TorqueCheck
from planner.core.lie import quat_from_rotation
from planner.motion.footholds import foothold_candidates
from planner.motion.heuristics import (
    frame_from_directions,
    horizontal_axes,
    nominal_height_m,
    support_plane_W,
)
from planner.motion.leg_swing import can_lift

__all__ = [
    "BUDGET",
    "CANDIDATES",
    "HORIZON",
    "STANCE_REACH_SHARE",
    "SWING_REACH_SHARE",
    "SLACK_M",
    "Certificate",
    "ContactSearch",
    "SearchSettings",
    "certify_step",
    "leg_check",
    "leg_joints",
    "stance_rotation_W",
]

_Array = NDArray[np.float64]

HORIZON = 5  # steps searched ahead: a crawl cycle and the first leg's next step
BUDGET = 40  # certificates per search (a few ms each)
CANDIDATES = 6  # footholds tried per leg and stance
# the reach fractions of Theta2 (planner.problems.theta2's STANCE_REACH_FRACTION and
# SWING_REACH_FRACTION; tests/test_contact_search.py holds them equal): a certificate
# looser than the problem it certifies passes steps the problem cannot make
STANCE_REACH_SHARE = 0.96  # stance foot centres within this share of the leg's reach
SWING_REACH_SHARE = 0.92  # the swing leg's hip within this share of reach of its new foothold
HEIGHT_COST = 0.2  # margin [m] a metre of body height off the nominal one costs
HEIGHT_BAND_M = 0.01  # the other body positions tried keep the height this near nominal
TILTS = (1.0, 0.6)  # body tilts tried, as shares of the feet plane's slope
SLACK_M = 0.005  # margin a certificate keeps beyond the balance margin, for what it does
# not model (the body's tilt and the swing leg's mass move the COM, Theta2's other rows)
MARGIN_CAP_M = 0.1  # the margin maximised is capped here (beyond, stances are equally good)
KEY_M = 0.005  # stances and footholds compared on this grid (the failure memory)
FOLLOW_M = 0.01  # a stance this near the one a sequence expects continues that sequence
LATERAL_M = 0.04  # candidates up to this far sideways of the stride target


@dataclass
class SearchSettings:
    """Budgets and margins of the search (module constants as defaults)."""

    horizon: int = HORIZON
    budget: int = BUDGET
    candidates: int = CANDIDATES
    stance_reach_share: float = STANCE_REACH_SHARE
    swing_reach_share: float = SWING_REACH_SHARE
    balance_margin_m: float = 0.025
    clearance_m: float = 0.02
    slack_m: float = SLACK_M


@dataclass
class Certificate:
    """A body position certifying a step, or why none exists.

    ``margin_m``: the COM's distance inside the three-foot triangle beyond the balance
    margin (>= the settings' slack when certified; -inf when the cone program is
    infeasible).
    """

    ok: bool
    margin_m: float
    body_W: _Array | None = None
    why: str = ""
    rotation_W: _Array | None = None  # the body's orientation with ``body_W``
    com_W: _Array | None = None  # the COM there, the legs at their lift-off joints


def stance_rotation_W(feet_W: _Array, forward_W: _Array, tilt: float = 1.0) -> _Array:
    """Body rotation with z_B normal to the feet's least-squares plane, x_B along forward.

    ``tilt`` < 1 scales the plane's slope (a body less tilted than its feet).
    """
    g, _ = support_plane_W(feet_W)
    n = np.array([-tilt * g[0], -tilt * g[1], 1.0])
    return frame_from_directions(np.asarray(forward_W, float), n / np.linalg.norm(n))


def _inward_edges(tri_xy: _Array) -> tuple[_Array, _Array]:
    """(unit inward normals (3, 2), offsets (3,)) of a triangle: inside iff n.x >= d."""
    c = tri_xy.mean(axis=0)
    normals, offsets = [], []
    for k in range(3):
        a, b = tri_xy[k], tri_xy[(k + 1) % 3]
        e = b - a
        n = np.array([-e[1], e[0]])
        norm = float(np.linalg.norm(n))
        if norm < 1e-12:
            n = np.zeros(2)
        else:
            n /= norm
        if n @ (c - a) < 0.0:
            n = -n
        normals.append(n)
        offsets.append(float(n @ a))
    return np.array(normals), np.array(offsets)


def _search_consts(robot) -> tuple[_Array, _Array]:
    """(hip points (4, 3), whole-body COM at theta_nor (3,)), body frame [m]."""
    hips = np.array([hip_point_B(leg) for leg in robot.legs])
    return hips, kinematics_of(robot).com_B(robot.theta_nor)


def certify_step(
    robot,
    feet_W: _Array,
    leg: int,
    foothold_W: _Array,
    rotation_W: _Array,
    z_floor_m: float,
    settings: SearchSettings,
    terrain=None,
    mu: float | None = None,
) -> Certificate:
    """Certificate of ``leg`` stepping from ``feet_W`` (4, 3 contacts) to ``foothold_W``.

    The body position b maximises the COM's margin t beyond ``balance_margin_m`` in the
    triangle of the other three feet, subject to every foot centre of the stance within
    ``stance_reach_share`` of its reach of the hip at b, the swing leg's hip within
    ``swing_reach_share`` of its reach of the new foot centre, the body origin at least
    ``z_floor_m`` high, and its height over the stance near the nominal one (a small
    cost). The COM is first the one at theta_nor, then the ones at the legs' joints there
    (lift-off and touch-down; the legs' mass moves it). Certified when t >= ``slack_m`` and
    :func:`leg_check` finds nothing there (its links and torques only with ``terrain``
    and ``mu``), or
    at one of the positions towards the ends, along x_B, of those keeping t >= ``slack_m``
    (a trailing leg's links ask for the body behind, a leading one's ahead).
    """
    feet = np.asarray(feet_W, float).reshape(4, 3)
    new = np.asarray(foothold_W, float).reshape(3)
    R = np.asarray(rotation_W, float)
    body = _BodyProgram(robot, feet, leg, new, R, z_floor_m, settings)
    _, com_B = robot_cached(robot, "_search_consts", _search_consts)
    x = body.solve([R @ com_B])
    if x is None:
        return Certificate(False, -math.inf, None, "no body position")
    poses = leg_joints(robot, feet, leg, new, R, x[:3])
    if isinstance(poses, list):  # the COM at the legs' joints there
        coms = [R @ kinematics_of(robot).com_B(th) for th in poses]
        again = body.solve(coms)
        x = x if again is None else again
    if x[3] < settings.slack_m:
        return Certificate(False, float(x[3]), x[:3], "the COM cannot keep the margin")

    def certified(b: _Array, margin_m: float) -> Certificate | str:
        poses = leg_joints(robot, feet, leg, new, R, b)
        why = leg_check(robot, feet, leg, new, R, b, settings.balance_margin_m, terrain, mu, poses)
        if why:
            return why
        com = R @ kinematics_of(robot).com_B(poses[0]) + b  # the legs at lift-off
        return Certificate(True, margin_m, b, rotation_W=R, com_W=com)

    first = certified(x[:3], float(x[3]))
    if not isinstance(first, str):
        return first
    ends = [e for e in (body.end(x, -1.0), body.end(x, 1.0)) if e is not None]
    for b in [0.5 * (x[:3] + e) for e in ends] + ends:
        cert = certified(b, body.margin(b))
        if not isinstance(cert, str):
            return cert
    return Certificate(False, float(x[3]), x[:3], first)


class _BodyProgram:
    """The cone program of :func:`certify_step` for one step, for a few COM models.

    Variables (b_x, b_y, b_z, t, s): the body position, the margin beyond the balance
    margin, and the body height's distance from the nominal one.
    """

    def __init__(self, robot, feet, leg, new, R, z_floor_m, settings: SearchSettings):
        self.settings, self.R = settings, R
        stay = [j for j in range(4) if j != leg]
        self.normals, self.offsets = _inward_edges(feet[stay, :2])
        after = feet.copy()
        after[leg] = new
        n_up = R[:, 2]
        h_nom = float(n_up @ after.mean(axis=0)) + nominal_height_m(robot)
        rows = [[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, -1.0, 0.0, 0.0], [*n_up, 0.0, -1.0],
                [*(-n_up), 0.0, -1.0]]  # fmt: skip
        self.lin = (rows, [MARGIN_CAP_M, -float(z_floor_m), h_nom, -h_nom])
        up = n_up * float(robot.foot_radius_m)  # contact -> sphere centre (approximately)
        hips_B, _ = robot_cached(robot, "_search_consts", _search_consts)
        balls = [(j, feet[j] + up, settings.stance_reach_share) for j in range(4)]
        balls.append((leg, new + up, settings.swing_reach_share))
        rows, rhs = [], []
        for j, c, share in balls:  # (r, b + R h_j - c) in the second-order cone
            rows += [[0.0] * 5, [-1.0, 0, 0, 0, 0], [0, -1.0, 0, 0, 0], [0, 0, -1.0, 0, 0]]
            rhs += [share * float(robot.reach_m[j]), *(R @ hips_B[j] - c)]
        self.balls = (rows, rhs, [clarabel.SecondOrderConeT(4)] * len(balls))
        self.coms: list[_Array] = []

    def _margin_rows(self, coms) -> tuple[list, list]:
        """n.(b + com)_xy - d - balance margin >= t, for every edge and COM."""
        rows, rhs = [], []
        for com in coms:
            for n, d in zip(self.normals, self.offsets, strict=True):
                rows.append([-n[0], -n[1], 0.0, 1.0, 0.0])
                rhs.append(float(n @ com[:2]) - d - self.settings.balance_margin_m)
        return rows, rhs

    def solve(self, coms: list[_Array]) -> _Array | None:
        """The largest margin (height cost subtracted) for ``coms``, or None."""
        self.coms = coms
        rows, rhs = self._margin_rows(coms)
        rows, rhs = rows + self.lin[0], rhs + self.lin[1]
        return self._run(rows, rhs, [0.0, 0.0, 0.0, -1.0, HEIGHT_COST])

    def end(self, x: _Array, sign: float) -> _Array | None:
        """The body position farthest along ``sign`` x_B keeping t >= slack.

        The height stays no farther from nominal than at ``x`` (or ``HEIGHT_BAND_M``).
        """
        rows, rhs = self._margin_rows(self.coms)
        rows = rows + self.lin[0] + [[0.0, 0.0, 0.0, -1.0, 0.0], [0.0] * 4 + [1.0]]
        rhs = rhs + self.lin[1] + [-self.settings.slack_m, max(float(x[4]), HEIGHT_BAND_M)]
        e = self._run(rows, rhs, [*(sign * self.R[:, 0]), 0.0, 0.0])
        return None if e is None else e[:3]

    def margin(self, b: _Array) -> float:
        """The margin t of body position ``b`` (the least over the COM models)."""
        return min(
            float(np.min(self.normals @ (b[:2] + com[:2]) - self.offsets))
            for com in self.coms
        ) - self.settings.balance_margin_m  # fmt: skip

    def _run(self, rows: list, rhs: list, q: list) -> _Array | None:
        A = sp.csc_matrix(np.array(rows + self.balls[0], float))
        s = clarabel.DefaultSettings()
        s.verbose = False
        cones = [clarabel.NonnegativeConeT(len(rows)), *self.balls[2]]
        b = np.array(rhs + self.balls[1], float)
        res = clarabel.DefaultSolver(sp.csc_matrix((5, 5)), np.asarray(q, float), A, b, cones,
                                     s).solve()  # fmt: skip
        if str(res.status) not in ("Solved", "AlmostSolved"):
            return None
        return np.asarray(res.x, float)


def leg_joints(
    robot, feet_W: _Array, leg: int, foothold_W: _Array, rotation_W: _Array, body_W: _Array
) -> list[_Array] | str:
    """The legs' joints at lift-off and touch-down of ``leg`` from a body pose, or why none.

    Paden-Kahan IK (section 4.5) of every foot centre, and of the swing leg's new one,
    within the joint limits, either knee branch (the leg's own first).
    """
    kin = kinematics_of(robot)
    R, b = np.asarray(rotation_W, float), np.asarray(body_W, float)
    up = R[:, 2] * float(robot.foot_radius_m)
    targets = [*(np.asarray(feet_W, float).reshape(4, 3) + up), np.asarray(foothold_W) + up]
    joints = np.zeros((5, 3))
    for k, c in enumerate(targets):
        j = leg if k == 4 else k
        target_B = R.T @ (c - b)
        # Newton from theta_nor (a few FK evaluations), else Paden-Kahan on both branches
        ik = kin.ik_leg_near(j, target_B, robot.theta_nor[j], max_step_rad=math.inf,
                             closest=False)  # fmt: skip
        if not ik.reachable or kin.knee_direction(j, ik.joints_rad) != robot.legs[j].knee_direction:
            ik = kin.ik_leg(j, target_B, closest=False)
        if not ik.reachable:
            which = "its new foothold" if k == 4 else "its foot"
            return f"{robot.legs[j].name} cannot reach {which} (joint limits)"
        joints[k] = ik.joints_rad
    land = joints[:4].copy()
    land[leg] = joints[4]
    return [joints[:4], land]


def leg_check(
    robot, feet_W: _Array, leg: int, foothold_W: _Array, rotation_W: _Array, body_W: _Array,
    balance_margin_m: float, terrain=None, mu: float | None = None, poses=None,
) -> str:  # fmt: skip
    """What the certificate's reach balls do not model, at body pose (``rotation_W``, ``body_W``).

    Why the pose cannot carry the step ("" when it can): a foot centre out of its leg's
    joint limits (:func:`leg_joints`); the COM at those joints less than
    ``balance_margin_m`` inside the triangle of the three feet that stay, with the swing
    leg's joints at lift-off and at touch-down; with ``terrain``, a thigh or shank nearer
    the sharp terrain than the planner's own path margin there
    (:meth:`planner.body.links.LegLinks.path_margin`), or a swing leg that cannot leave
    its foothold or come down on the new one with its links clear
    (:func:`planner.motion.leg_swing.can_lift`, the ends of a joint-space swing); with
    ``mu`` too, a support joint beyond ``COMMANDED_TORQUE_FRACTION`` of its effort in the
    commanded forces on three feet (:class:`planner.body.torques.TorqueCheck`, Theta2's
    torque rows). ``poses``: :func:`leg_joints`' answer there, when known.
    """
    if poses is None:
        poses = leg_joints(robot, feet_W, leg, foothold_W, rotation_W, body_W)
    if isinstance(poses, str):
        return poses
    kin = kinematics_of(robot)
    R, b = np.asarray(rotation_W, float), np.asarray(body_W, float)
    feet = np.asarray(feet_W, float).reshape(4, 3)
    stay = np.delete(feet, leg, axis=0)
    for th in poses:
        if support_margin_m(stay, R @ kin.com_B(th) + b) < balance_margin_m:
            return "the COM at the legs' joints leaves the balance margin"
    if terrain is None:
        return ""
    links = leg_links(robot)
    quat = quat_from_rotation(R)
    qs = [robot.q_from(b, quat, th) for th in poses]  # lift-off, touch-down
    for margin in links.path_margins(terrain, qs, [(), ()])[0]:  # one terrain query
        if np.any(margin < 0.0):
            return f"{links.describe(int(np.argmin(margin)))} inside its margin from the terrain"
    name = robot.legs[leg].name
    after = feet.copy()
    after[leg] = np.asarray(foothold_W, float).reshape(3)
    if not can_lift(robot, terrain, State(b, R, feet, poses[0]), leg):
        return f"{name} cannot lift its foot with its links clear"
    if not can_lift(robot, terrain, State(b, R, after, poses[1]), leg):
        return f"{name} cannot come down on its new foothold with its links clear"
    if mu is None:
        return ""
    check = robot_cached(robot, "_search_torques", TorqueCheck)
    stay_legs = [j for j in range(4) if j != leg]
    for q, contacts in zip(qs, (feet, after), strict=True):
        normals = np.asarray(terrain.normal(contacts), float).reshape(4, 3)
        res = check.solve(q, stay_legs, mu, normals, least_squares=True)
        if not res.ratio <= COMMANDED_TORQUE_FRACTION:
            return f"a support joint would need {res.ratio:.0%} of its effort"
    return ""


class ContactSearch:
    """Depth-first search over the next gait steps' footholds (module docstring).

    ``forward(point_W)``: the guide path's horizontal forward direction near a point;
    ``z_floor(feet_W)``: the least body-origin height over a stance.
    """

    def __init__(
        self,
        robot,
        terrain,
        mu: float,
        forward: Callable[[_Array], _Array],
        z_floor: Callable[[_Array], float],
        settings: SearchSettings | None = None,
    ):
        self.robot, self.terrain, self.mu = robot, terrain, float(mu)
        self.forward, self.z_floor = forward, z_floor
        self.settings = settings or SearchSettings()
        self.failed: set[tuple] = set()
        self.sequence: tuple[_Array, list] | None = None  # (its start stance, its steps)
        self.stats = {"searches": 0, "certificates": 0, "certified": 0, "found": 0}
        self.stats |= {"realised": 0, "unrealised": 0}  # searched first steps, by Theta

    # ---- memory of the steps the Theta problems could not realise ------------------------
    @staticmethod
    def _key(feet_W: _Array, leg: int, foothold_W: _Array) -> tuple:
        grid = np.round(np.concatenate([np.ravel(feet_W), np.ravel(foothold_W)]) / KEY_M)
        return (int(leg), *grid.astype(int).tolist())

    def mark_failed(self, feet_W: _Array, leg: int, foothold_W: _Array) -> None:
        """Remember that ``leg`` could not be moved from ``feet_W`` to ``foothold_W``."""
        self.failed.add(self._key(feet_W, leg, foothold_W))
        self.stats["unrealised"] += 1

    def mark_realised(self) -> None:
        """A searched step was made by the Theta problems (the certificates' record)."""
        self.stats["realised"] += 1

    # ---- the search ------------------------------------------------------------------------
    def candidates(self, feet_W: _Array, leg: int, body_W: _Array, stride_m: float) -> list:
        """Footholds for ``leg``: around its foot a stride ahead, safe and within reach."""
        f = self.forward(feet_W[leg])
        fwd, _ = horizontal_axes(f)
        target = feet_W[leg] + stride_m * fwd
        target[2] = float(self.terrain.height(target[0], target[1]))
        R = stance_rotation_W(feet_W, f)
        return foothold_candidates(
            self.robot, self.terrain, leg, target, fwd, body_W, R, self.mu,
            not_behind_W=feet_W[leg], max_lateral_m=LATERAL_M,
            limit=self.settings.candidates,
        )  # fmt: skip

    def certify(self, feet_W: _Array, leg: int, foothold_W: _Array) -> Certificate:
        """:func:`certify_step` with this search's rotation, floor and settings."""
        self.stats["certificates"] += 1
        after = feet_W.copy()
        after[leg] = foothold_W
        forward, floor = self.forward(feet_W.mean(axis=0)), self.z_floor(after)
        first = None
        for tilt in TILTS:  # the body's pitch and roll are not variables of the program
            R = stance_rotation_W(after, forward, tilt)
            cert = certify_step(
                self.robot, feet_W, leg, foothold_W, R, floor, self.settings, self.terrain,
                self.mu,
            )  # fmt: skip
            cert.rotation_W = R
            first = first or cert
            if cert.ok:
                break
        cert = cert if cert.ok else first
        self.stats["certified"] += int(cert.ok)
        return cert

    def search(
        self,
        feet_W: _Array,
        body_W: _Array,
        legs: Sequence[int],
        stride_m: float,
        first_W: _Array | None = None,
        only_first: bool = False,
    ) -> list[tuple[int, _Array, Certificate]]:
        """A certified sequence of steps of ``legs`` (in order) from ``feet_W``.

        Depth-first, each leg's candidates best first (``first_W``, the step's own
        proposal, before the first leg's, then the next foothold of the sequence found
        before where the walk followed it; with ``only_first`` the only first step),
        failed edges pruned, at most ``budget`` certificates: the first sequence certified
        to the end is returned, so a proposal that leaves every later step a certified
        foothold is kept as it is. When the budget runs out first, the deepest sequence
        certified so far (empty when the first step has no certified foothold).
        """
        self.stats["searches"] += 1
        st = self.settings
        legs = list(legs)[: st.horizon]
        # the sequence found before, where the walk followed it: its next foothold second
        planned = None if only_first else self._next_of_sequence(feet_W, legs[0])
        deepest: list = []
        spent = 0
        cap = st.budget  # certificates the subtree in hand may spend up to

        def dive(feet: _Array, body: _Array, steps: list) -> list | None:
            nonlocal deepest, spent, cap
            if len(steps) > len(deepest):
                deepest = steps
            if len(steps) == len(legs):
                return steps
            leg = legs[len(steps)]
            found = self.candidates(feet, leg, body, stride_m)
            if not steps:
                firsts = [c for c in (first_W, planned) if c is not None]
                others = [] if only_first else found
                found = []
                for c in [np.asarray(c, float).reshape(3) for c in firsts] + others:
                    if all(np.linalg.norm(c - f) > KEY_M for f in found):
                        found.append(c)
            for k, c in enumerate(found):
                if not steps:  # the proposal leaves the planned foothold half the budget
                    cap = st.budget // 2 if k == 0 and planned is not None else st.budget
                if spent >= cap:
                    return None
                if self._key(feet, leg, c) in self.failed:
                    continue
                spent += 1
                cert = self.certify(feet, leg, c)
                if not cert.ok:
                    continue
                after = feet.copy()
                after[leg] = c
                done = dive(after, cert.body_W, [*steps, (leg, c, cert)])
                if done is not None:
                    return done
            return None

        done = dive(np.array(feet_W, float).reshape(4, 3), np.asarray(body_W, float), [])
        steps = done if done is not None else deepest
        if steps:
            self.stats["found"] += 1
        if not only_first:
            self.sequence = (np.array(feet_W, float).reshape(4, 3), steps) if steps else None
        return steps

    def _next_of_sequence(self, feet_W: _Array, leg: int) -> _Array | None:
        """The last sequence's next foothold, or None.

        None unless ``feet_W`` is that sequence's stance after its first step (within
        ``FOLLOW_M``) and ``leg`` its next leg.
        """
        if self.sequence is None or len(self.sequence[1]) < 2:
            return None
        start, steps = self.sequence
        expected = start.copy()
        expected[steps[0][0]] = steps[0][1]
        near = np.max(np.abs(np.asarray(feet_W, float).reshape(4, 3) - expected)) <= FOLLOW_M
        return steps[1][1] if near and steps[1][0] == leg else None
