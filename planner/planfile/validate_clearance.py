"""The validator's clearance checks: body box, leg links and swing feet vs the sharp terrain.

``body_clearance``, ``leg_clearance`` and ``swing_clearance`` of
:func:`planner.planfile.validate.check_plan` (see its module docstring): a tile bound
first, exact distances (:func:`~planner.planfile.validate_surface.sharp_surface_distance`)
where a sample comes close, and between two samples where the executor's linear joint
interpolation sweeps a leg.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from planner.body.links import LegLinks
from planner.motion.interpolate import BETWEEN_SAMPLES_RAD, BETWEEN_STEP_RAD, between_q
from planner.planfile.validate_report import CheckReport, _leg, _mm
from planner.planfile.validate_surface import (
    _body_points_B,
    _rotations_from_quats,
    _TileMax,
    sharp_surface_distance,
)

_Array = NDArray[np.float64]
_LEG_EXACT_M = 0.004  # leg clearances are exact below this [m]; above, a lower bound


class _ClearanceChecks:
    """The clearance checks of :class:`planner.planfile.validate._Checker`.

    A mixin: the checker provides ``plan``, ``tol``, ``robot``, ``terrain``, ``rho``,
    ``tiles``, ``add`` and ``kinematics``.
    """

    def body_clearance(self, report: CheckReport) -> None:
        """Body box P vs the sharp terrain: a tile bound first, exact points where close."""
        sm, tol = self.plan.samples, self.tol
        rot = _rotations_from_quats(sm.q[:, 3:7])
        verts = np.einsum("nij,kj->nki", rot, self.robot.body_vertices_B) + sm.q[:, None, :3]
        pad = _TileMax.NODE_M
        boxes = np.column_stack(
            [
                verts[:, :, 0].min(axis=1) - pad,
                verts[:, :, 0].max(axis=1) + pad,
                verts[:, :, 1].min(axis=1) - pad,
                verts[:, :, 1].max(axis=1) + pad,
            ]
        )
        # lowest vertex over the highest terrain node under the footprint: a lower bound
        bound = verts[:, :, 2].min(axis=1) - self.tiles.max_in(boxes) - _TileMax.SLACK_M
        faces = _body_points_B(self.robot, tol.body_grid_m)
        # exact points for the samples within 1 cm of touching, and the 8 closest
        todo = np.union1d(
            np.flatnonzero(bound < tol.body_clearance_m + 0.01), np.argsort(bound)[:8]
        )
        exact = np.full(len(sm), np.inf)
        for a in range(0, len(todo), 32):
            pts, owner = [], []
            for k in todo[a : a + 32]:
                for normal, p_b in faces:
                    if (rot[k] @ normal)[2] < -1e-9:
                        pts.append(p_b @ rot[k].T + sm.q[k, :3])
                        owner.append(np.full(len(p_b), k))
            pts_w = np.concatenate(pts)
            own = np.concatenate(owner)
            h = np.asarray(self.terrain.height_sharp(pts_w[:, 0], pts_w[:, 1])).reshape(-1)
            np.minimum.at(exact, own, pts_w[:, 2] - h)
        rest = np.setdiff1d(np.arange(len(sm)), todo)
        best = float(exact.min())
        if len(rest):  # not measured exactly: lowest vertex over the tile maximum
            best = min(best, float(bound[rest].min() + _TileMax.SLACK_M))
        report.min_body_clearance_m = best
        for k in np.flatnonzero(exact < tol.body_clearance_m):
            self.add(
                "body_clearance",
                f"sample {k}",
                None,
                exact[k],
                tol.body_clearance_m,
                f"body box reaches {_mm(-exact[k])} below the sharp terrain (least clearance "
                f"{_mm(tol.body_clearance_m)})",
            )

    def leg_clearance(self, report: CheckReport) -> None:
        """Thigh and shank capsules vs the sharp terrain (``leg_clearance``).

        At every sample, and between two samples where a joint moves more than
        ``BETWEEN_SAMPLES_RAD`` (the executor interpolates the joints linearly: a knee
        flipping between two clear samples can sweep its shank through the terrain), at
        configurations ``BETWEEN_STEP_RAD`` apart.
        """
        sm, tol = self.plan.samples, self.tol
        links = LegLinks(self.robot)
        per = self._link_clearances(links, sm.q)
        report.min_leg_clearance_m = float(per.min()) if per.size else math.nan
        for k, c in zip(*np.nonzero(per < tol.leg_clearance_m), strict=True):
            self._leg_violation(links, f"sample {k}", c, per[k, c])
        for k in range(len(sm) - 1):
            jump = float(np.max(np.abs(sm.q[k + 1, 7:] - sm.q[k, 7:])))
            if jump <= BETWEEN_SAMPLES_RAD:
                continue
            m = int(math.ceil(jump / BETWEEN_STEP_RAD))
            qs = np.array([between_q(sm.q[k], sm.q[k + 1], u) for u in np.arange(1, m) / m])
            mid = self._link_clearances(links, qs).min(axis=0)
            report.min_leg_clearance_m = min(report.min_leg_clearance_m, float(mid.min()))
            for c in np.flatnonzero(mid < tol.leg_clearance_m):
                self._leg_violation(links, f"sample {k}", c, mid[c], f" between it and {k + 1}")

    def _leg_violation(self, links: LegLinks, where: str, c: int, value: float, extra="") -> None:
        cap = links.capsules[c]
        tol = self.tol.leg_clearance_m
        self.add(
            "leg_clearance",
            where,
            cap.leg,
            value,
            tol,
            f"{_leg(cap.leg)} {cap.link} ({cap.urdf_link}) reaches {_mm(-value)} into "
            f"the sharp terrain{extra} (least clearance {_mm(tol)})",
        )

    def _link_clearances(self, links: LegLinks, q_all: _Array) -> _Array:
        """(N, capsules) clearances [m] of the leg links at configurations ``q_all``."""
        from scipy.ndimage import maximum_filter

        tol = self.tol
        n, P = len(q_all), len(links.owner)
        pts = np.empty((n, P, 3))
        for k in range(n):
            pts[k] = links.axis_points_W(q_all[k])
        flat = pts.reshape(-1, 3)
        rad = np.tile(links.radius, n)
        # bound: highest terrain node within (radius + node) of a point, on a 5 mm raster
        node = _TileMax.NODE_M
        reach = float(links.radius.max()) + 2.0 * node
        x0, y0 = flat[:, 0].min() - reach, flat[:, 1].min() - reach
        nx = int(math.ceil((flat[:, 0].max() + reach - x0) / node)) + 1
        ny = int(math.ceil((flat[:, 1].max() + reach - y0) / node)) + 1
        H = self.terrain.height_sharp_grid(x0 + node * np.arange(nx), y0 + node * np.arange(ny))
        M = maximum_filter(H, size=2 * int(math.ceil(reach / node)) + 1, mode="nearest")
        ix = np.clip(np.rint((flat[:, 0] - x0) / node).astype(int), 0, nx - 1)
        iy = np.clip(np.rint((flat[:, 1] - y0) / node).astype(int), 0, ny - 1)
        clear = flat[:, 2] - rad - M[iy, ix] - _TileMax.SLACK_M  # a lower bound
        near = np.flatnonzero(clear < tol.leg_clearance_m + _LEG_EXACT_M)
        if len(near):
            search = float(rad[near].max()) + tol.leg_clearance_m + _LEG_EXACT_M + 2e-3
            d = sharp_surface_distance(self.terrain, flat[near], search, tol.surface_step_m)
            # a distance clipped at the search radius is only known to be at least that
            clear[near] = np.where(np.abs(d) < search, d - rad[near], search - rad[near])
        per = np.full((n, len(links.capsules)), np.inf)
        owner = np.tile(links.owner, n)
        sample = np.repeat(np.arange(n), P)
        np.minimum.at(per, (sample, owner), clear)
        # refine along the axis around the closest point of the capsules near the limit
        for k, c in zip(*np.nonzero(per < tol.leg_clearance_m + 1e-3), strict=True):
            per[k, c] = min(per[k, c], self._capsule_clearance(links, q_all[k], c))
        return per

    def _capsule_clearance(self, links: LegLinks, q: _Array, c: int) -> float:
        """Clearance of capsule c at q from points 0.2 mm apart along its whole axis."""
        cap = links.capsules[c]
        a, b = (s[c] for s in links.segments_W(q))
        u = np.linspace(0.0, 1.0, max(2, int(math.ceil(cap.length_m / 2e-4)) + 1))[:, None]
        p = (1.0 - u) * a + u * b
        gap = p[:, 2] - np.asarray(self.terrain.height_sharp(p[:, 0], p[:, 1])).reshape(-1)
        search = cap.radius_m + self.tol.leg_clearance_m + _LEG_EXACT_M + 2e-3
        sel = np.flatnonzero(gap < search)
        if not len(sel):
            return float(gap.min() - cap.radius_m)
        d = sharp_surface_distance(self.terrain, p[sel], search, self.tol.surface_step_m)
        return float(min(d.min(), search) - cap.radius_m)

    def swing_clearance(self, centres: _Array, report: CheckReport) -> None:
        """Swing spheres vs the sharp terrain: a tile bound first, distances where close."""
        sm, tol = self.plan.samples, self.tol
        ks, ls = np.nonzero(~sm.contact)
        if not len(ks):
            return
        clear = self._sphere_clearances(centres[ks, ls])
        report.min_swing_clearance_m = float(clear.min())
        for j in np.flatnonzero(clear < -tol.swing_penetration_m):
            self._swing_violation(ks[j], ls[j], clear[j])
        self._swing_between_samples(centres, report)

    def _sphere_clearances(self, c: _Array) -> _Array:
        """(N,) clearances [m] of foot spheres centred at ``c`` (N, 3) over the sharp terrain.

        A tile bound first; the exact distance where it is under 1 mm.
        """
        rho = self.rho
        reach = rho + _TileMax.NODE_M
        boxes = np.column_stack(
            [c[:, 0] - reach, c[:, 0] + reach, c[:, 1] - reach, c[:, 1] + reach]
        )
        clear = c[:, 2] - rho - self.tiles.max_in(boxes) - _TileMax.SLACK_M  # a lower bound
        near = np.flatnonzero(clear < 1e-3)
        if len(near):
            d = sharp_surface_distance(self.terrain, c[near], rho + 1e-3, self.tol.surface_step_m)
            clear[near] = d - rho
        return clear

    def _swing_violation(self, k: int, leg: int, clear: float, extra: str = "") -> None:
        tol, rho = self.tol, self.rho
        self.add(
            "swing_clearance",
            f"sample {k}",
            leg,
            -clear,
            tol.swing_penetration_m,
            f"{_leg(leg)} swing foot sphere penetrates the sharp terrain by "
            f"{'at least ' if -clear >= rho else ''}{_mm(-clear)}{extra} (limit "
            f"{_mm(tol.swing_penetration_m)})",
        )

    def _swing_between_samples(self, centres: _Array, report: CheckReport) -> None:
        """Swing spheres between two samples where their leg's joints jump (``swing_clearance``).

        Where a joint of the leg moves more than ``BETWEEN_SAMPLES_RAD``, at configurations
        ``BETWEEN_STEP_RAD`` apart: the executor interpolates the joints linearly, and a
        knee flipping between two clear samples can sweep the foot through the terrain (as
        :meth:`leg_clearance` does the links). An interval that starts or ends with the
        foot down may go as deep as the foot stands there (near an edge a foot on the
        smooth terrain overlaps the sharp one a little, ``foot_off_sharp_surface``).
        """
        sm, tol = self.plan.samples, self.tol
        where, swept = [], []  # (interval, leg) of each swept sphere centre
        for k in range(len(sm) - 1):
            legs = [i for i in range(4) if not (sm.contact[k, i] and sm.contact[k + 1, i])]
            dq = np.abs(sm.q[k + 1, 7:] - sm.q[k, 7:]).reshape(4, 3).max(axis=1)
            if not legs or float(dq[legs].max()) <= BETWEEN_SAMPLES_RAD:
                continue
            m = int(math.ceil(float(dq[legs].max()) / BETWEEN_STEP_RAD))
            for u in np.arange(1, m) / m:
                feet = self.kinematics(between_q(sm.q[k], sm.q[k + 1], u))[0]
                where += [(k, i) for i in legs]
                swept += [feet[i] for i in legs]
        if not swept:
            return
        clear = self._sphere_clearances(np.array(swept))
        report.min_swing_clearance_m = min(report.min_swing_clearance_m, float(clear.min()))
        worst: dict[tuple[int, int], float] = {}
        for j in np.flatnonzero(clear < -tol.swing_penetration_m):
            worst[where[j]] = min(worst.get(where[j], 0.0), float(clear[j]))
        for (k, i), value in sorted(worst.items()):
            down = [kk for kk in (k, k + 1) if sm.contact[kk, i]]
            ends = self._sphere_clearances(centres[down, i]) if down else np.zeros(0)
            if value < min(float(ends.min(initial=0.0)), 0.0) - tol.swing_penetration_m:
                self._swing_violation(k, i, value, f" between it and {k + 1}")
