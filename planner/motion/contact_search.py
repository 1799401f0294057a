"""Contact-sequence search: footholds chosen a gait cycle ahead, with certificates.

Beyond the paper: section 8.2's queue takes one foothold at a time (Lambda_t, eq. 13) and
learns that a leg was left behind only when no body move reaches it. Here the next
``horizon`` steps of the gait are searched together (a depth-first search over stances:
the four footholds, the step's own proposal first, then each leg's candidates best first),
each step an edge from a stance to the stance with one leg moved to a
candidate foothold (:func:`planner.motion.footholds.foothold_candidates`: reachable, safe
under the sharp terrain, scored by progress, posture and slope). An edge is kept only with
a *certificate*: a body position (its orientation fixed by the feet's plane and the guide
path's direction) at which

- the COM (the whole-body COM at theta_nor) is at least the balance margin inside the
  triangle of the three feet that stay (the three-foot support margin of Theta2, 7.3),
- every foot centre, the swing leg's old and new one both, is within ``REACH_SHARE`` of
  its leg's reach of the hip (the workspace zeta_i of 4.4),
- the body's bottom face is ``clearance_m`` above the sharp terrain under the stance.

Such a body position is found by a second-order cone program (Clarabel): the reach
balls and the shrunk triangle are convex, and the largest margin is maximised. Because
consecutive certified positions both reach the four feet of the stance between them and
keep the COM over it, the body move between them stays certified too (convexity). The
Theta problems (the paper's continuous layer) then realise the steps; an edge they
cannot realise is remembered (:meth:`ContactSearch.mark_failed`) and pruned from later
searches, which repair from the stance the walk is in.
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
from planner.motion.footholds import foothold_candidates
from planner.motion.heuristics import frame_from_directions, horizontal_axes, support_plane_W

__all__ = [
    "BUDGET",
    "CANDIDATES",
    "HORIZON",
    "REACH_SHARE",
    "SLACK_M",
    "Certificate",
    "ContactSearch",
    "SearchSettings",
    "certify_step",
    "stance_rotation_W",
]

_Array = NDArray[np.float64]

HORIZON = 4  # steps searched ahead: one crawl cycle
BUDGET = 40  # certificates per search (a few ms each)
CANDIDATES = 6  # footholds tried per leg and stance
REACH_SHARE = 0.97  # foot centres within this share of the leg's reach of the hip
SLACK_M = 0.005  # margin a certificate keeps beyond the balance margin, for what it does
# not model (the body's tilt and the swing leg's mass move the COM, Theta2's other rows)
MARGIN_CAP_M = 0.1  # the margin maximised is capped here (beyond, stances are equally good)
KEY_M = 0.005  # stances and footholds compared on this grid (the failure memory)
LATERAL_M = 0.04  # candidates up to this far sideways of the stride target


@dataclass
class SearchSettings:
    """Budgets and margins of the search (module constants as defaults)."""

    horizon: int = HORIZON
    budget: int = BUDGET
    candidates: int = CANDIDATES
    reach_share: float = REACH_SHARE
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


def stance_rotation_W(feet_W: _Array, forward_W: _Array) -> _Array:
    """Body rotation with z_B normal to the feet's least-squares plane, x_B along forward."""
    g, _ = support_plane_W(feet_W)
    n = np.array([-g[0], -g[1], 1.0])
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
) -> Certificate:
    """Certificate of ``leg`` stepping from ``feet_W`` (4, 3 contacts) to ``foothold_W``.

    The body position b maximises the COM's margin t beyond ``balance_margin_m`` in the
    triangle of the other three feet, subject to every foot centre (the swing leg's
    present and next one) within ``reach_share`` of its reach of the hip at b, and the
    body origin at least ``z_floor_m`` high. Certified when t >= ``slack_m``.
    """
    feet = np.asarray(feet_W, float).reshape(4, 3)
    new = np.asarray(foothold_W, float).reshape(3)
    R = np.asarray(rotation_W, float)
    rho = float(robot.foot_radius_m)
    up = R[:, 2] * rho  # contact -> sphere centre, along the body's normal (approximately)
    hips_B, com_B = robot_cached(robot, "_search_consts", _search_consts)
    com = R @ com_B
    stay = [j for j in range(4) if j != leg]
    normals, offsets = _inward_edges(feet[stay, :2])
    # variables x = (b_x, b_y, b_z, t); minimise -t
    rows, rhs, cones = [], [], []
    for n, d in zip(normals, offsets, strict=True):  # n.(b + com)_xy - d - m >= t
        rows.append([-n[0], -n[1], 0.0, 1.0])
        rhs.append(float(n @ com[:2]) - d - settings.balance_margin_m)
    rows.append([0.0, 0.0, 0.0, 1.0])
    rhs.append(MARGIN_CAP_M)
    rows.append([0.0, 0.0, -1.0, 0.0])
    rhs.append(-float(z_floor_m))
    cones.append(clarabel.NonnegativeConeT(len(rows)))
    centres = [(j, feet[j] + up) for j in range(4)] + [(leg, new + up)]
    for j, c in centres:  # (r, b + R h_j - c) in the second-order cone
        h = R @ hips_B[j]
        rows += [[0.0] * 4, [-1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 0]]
        rhs += [settings.reach_share * float(robot.reach_m[j]), *(h - c)]
        cones.append(clarabel.SecondOrderConeT(4))
    A = sp.csc_matrix(np.array(rows, float))
    s = clarabel.DefaultSettings()
    s.verbose = False
    q = np.array([0.0, 0.0, 0.0, -1.0])
    res = clarabel.DefaultSolver(sp.csc_matrix((4, 4)), q, A, np.array(rhs), cones, s).solve()
    status = str(res.status)
    if status not in ("Solved", "AlmostSolved"):
        return Certificate(False, -math.inf, None, f"no body position ({status})")
    x = np.asarray(res.x, float)
    if x[3] < settings.slack_m:
        return Certificate(False, float(x[3]), x[:3], "the COM cannot keep the margin")
    return Certificate(True, float(x[3]), x[:3])


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
        self.stats = {"searches": 0, "certificates": 0, "certified": 0, "found": 0}

    # ---- memory of the steps the Theta problems could not realise ------------------------
    @staticmethod
    def _key(feet_W: _Array, leg: int, foothold_W: _Array) -> tuple:
        grid = np.round(np.concatenate([np.ravel(feet_W), np.ravel(foothold_W)]) / KEY_M)
        return (int(leg), *grid.astype(int).tolist())

    def mark_failed(self, feet_W: _Array, leg: int, foothold_W: _Array) -> None:
        """Remember that ``leg`` could not be moved from ``feet_W`` to ``foothold_W``."""
        self.failed.add(self._key(feet_W, leg, foothold_W))

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
        R = stance_rotation_W(after, self.forward(feet_W.mean(axis=0)))
        cert = certify_step(
            self.robot, feet_W, leg, foothold_W, R, self.z_floor(after), self.settings
        )
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
        proposal, before the first leg's; with ``only_first`` the only first step),
        failed edges pruned, at most ``budget`` certificates: the first sequence certified
        to the end is returned, so a proposal that leaves every later step a certified
        foothold is kept as it is. When the budget runs out first, the deepest sequence
        certified so far (empty when the first step has no certified foothold).
        """
        self.stats["searches"] += 1
        st = self.settings
        legs = list(legs)[: st.horizon]
        deepest: list = []
        spent = 0

        def dive(feet: _Array, body: _Array, steps: list) -> list | None:
            nonlocal deepest, spent
            if len(steps) > len(deepest):
                deepest = steps
            if len(steps) == len(legs):
                return steps
            leg = legs[len(steps)]
            found = self.candidates(feet, leg, body, stride_m)
            if not steps and first_W is not None:
                first = np.asarray(first_W, float).reshape(3)
                others = [] if only_first else found
                found = [first] + [c for c in others if np.linalg.norm(c - first) > KEY_M]
            for c in found:
                if spent >= st.budget:
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
        return steps
