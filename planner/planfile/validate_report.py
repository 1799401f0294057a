"""The check's outcome: tolerances, violations and the report of one plan.

:class:`CheckTolerances` (SI units), :class:`Violation` (one failed check) and
:class:`CheckReport` (the violations and the summary figures) of
:func:`planner.planfile.validate.check_plan`.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from planner.body.robot import LEG_NAMES


@dataclass(frozen=True)
class CheckTolerances:
    """Tolerances of :func:`check_plan` (SI units: m, rad, N).

    Attributes
    ----------
    fk_m : keyframe FK vs stored feet.
    joint_rad : excursion past a joint limit.
    slip_m : sliding of a foot in contact between consecutive samples (travel minus rolling).
    on_terrain_m : ``|f_T|`` of a contact point on the smooth terrain.
    sharp_surface_m : distance of a contact point from the sharp surface; None: the
        terrain's largest smoothing width + 1 mm (6 mm by default).
    body_clearance_m : least height of the body box above the sharp terrain.
    swing_penetration_m : allowed penetration of a swing foot sphere into the sharp terrain.
    leg_clearance_m : least distance of a thigh or shank capsule to the sharp terrain.
    torque_rel : a joint torque may exceed its effort limit by this fraction.
    force_balance_rel : keyframe force/moment residual, as a fraction of m g.
    min_contacts : feet that must be down at every sample.
    balance_tol_N : margin the exact statics test must exceed; None: its default.
    body_grid_m : spacing of the points sampled on the body box's lower faces.
    surface_step_m : grid step of the sharp-surface distance search.

    """

    fk_m: float = 1e-6
    joint_rad: float = 1e-9
    slip_m: float = 1e-6
    on_terrain_m: float = 1e-4
    sharp_surface_m: float | None = None
    body_clearance_m: float = 0.0
    swing_penetration_m: float = 1e-4
    leg_clearance_m: float = 0.0
    torque_rel: float = 1e-6
    force_balance_rel: float = 1e-6
    min_contacts: int = 3
    balance_tol_N: float | None = None
    body_grid_m: float = 0.005
    surface_step_m: float = 1e-3


@dataclass(frozen=True)
class Violation:
    """One failed check.

    ``kind`` (see the module docstring), ``where`` ("sample 17" / "keyframe 3" / "robot",
    0-based indices), the 1-based ``leg`` (or None), the offending ``value`` and its
    ``limit`` (SI units), and a one-line ``message``.
    """

    kind: str
    where: str
    leg: int | None
    value: float
    limit: float
    message: str

    def __str__(self) -> str:
        return f"{self.where}: {self.kind}: {self.message}"


@dataclass
class CheckReport:
    """Outcome of :func:`check_plan`: the violations and a few summary figures.

    ``min_body_clearance_m``: least height of the body box over the sharp terrain (exact
    at the samples within 1 cm of the ground and the 8 closest, elsewhere the lowest
    vertex over the highest terrain node under the body);
    ``min_swing_clearance_m``: least distance of a swing sphere to the sharp surface
    (negative: penetration; a lower bound where the foot is far up); ``min_leg_clearance_m``:
    least distance of a thigh or shank capsule to the sharp terrain (exact below 4 mm, a
    lower bound above); ``max_torque_ratio``: largest joint torque over its effort limit
    (with the least demanding forces); ``min_balance_margin_N``:
    least force margin of the statics test; ``min_tip_margin_m``: least horizontal
    distance of the COM inside a three-leg support triangle (a figure, not a test: the
    planner keeps :data:`planner.body.stability.PATH_BALANCE_MARGIN_M`);
    ``min_sway_stiffness_N_per_m``: least sway stiffness of a three-leg stance where it
    begins, on the robot's servos with the commanded feed-forward (a figure:
    :mod:`planner.body.stiffness`; the planner keeps its bound); ``max_slip_m``:
    largest stance-foot sliding between samples (travel minus rolling). NaN when there was
    nothing to measure.
    """

    violations: list[Violation] = field(default_factory=list)
    n_samples: int = 0
    n_keyframes: int = 0
    min_body_clearance_m: float = math.nan
    min_swing_clearance_m: float = math.nan
    min_leg_clearance_m: float = math.nan
    min_balance_margin_N: float = math.nan
    min_tip_margin_m: float = math.nan
    max_torque_ratio: float = math.nan
    min_sway_stiffness_N_per_m: float = math.nan
    max_slip_m: float = math.nan
    elapsed_s: float = 0.0
    tolerances: CheckTolerances = field(default_factory=CheckTolerances)
    structure_only: bool = False  # a malformed plan: the other checks were skipped

    @property
    def ok(self) -> bool:
        """True when no check failed."""
        return not self.violations

    def by_kind(self) -> dict[str, int]:
        """Number of violations of each kind."""
        return dict(Counter(v.kind for v in self.violations))

    def summary(self) -> str:
        """One line: verdict, counts per kind, and the summary figures."""
        figs = (
            f"min body clearance {_mm(self.min_body_clearance_m)}, min swing clearance "
            f"{_mm(self.min_swing_clearance_m)}, min leg clearance "
            f"{_mm(self.min_leg_clearance_m)}, min balance margin "
            f"{self.min_balance_margin_N:.3g} N, min three-leg tip margin "
            f"{_mm(self.min_tip_margin_m)}, max joint torque "
            f"{100 * self.max_torque_ratio:.0f} % of its limit, min three-leg sway "
            f"stiffness {self.min_sway_stiffness_N_per_m:.0f} N/m, max stance slip "
            f"{_mm(self.max_slip_m)}"
        )
        head = f"checked {self.n_samples} samples and {self.n_keyframes} keyframes"
        if self.ok:
            return f"{head}: OK ({figs}; {self.elapsed_s:.2f} s)"
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(self.by_kind().items()))
        if self.structure_only:
            return (
                f"{head}: FAILED, {len(self.violations)} violations ({kinds}); no motion a "
                f"robot could execute, so the other checks were skipped ({self.elapsed_s:.2f} s)"
            )
        return (
            f"{head}: FAILED, {len(self.violations)} violations ({kinds}) ({figs}; "
            f"{self.elapsed_s:.2f} s)"
        )


def _mm(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{1e3 * x:.3g} mm"


def _leg(i: int) -> str:
    return f"leg {i + 1} ({LEG_NAMES[i]})"
