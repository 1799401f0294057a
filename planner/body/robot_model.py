"""The robot model's data: a leg's screw axes and limits, the whole robot (paper section 5).

Its own module so that :mod:`planner.body.kinematics` (which completes a :class:`Robot` with its
normal configuration and reach) and :mod:`planner.body.robot` (which reads one from a URDF)
import it without importing each other.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import pinocchio as pin


@dataclass
class Leg:
    """One leg: three revolute joints, hip to foot, at the zero configuration in body frame.

    ``axes_B[j]`` is the unit axis omega_{i,j} and ``points_B[j]`` the joint origin
    r^0_{i,j} (paper eq. 1-2); ``foot_B0`` is the foot sphere centre r^0_i.
    """

    name: str
    index: int  # 0-based; the paper's leg number is index + 1
    joint_names: tuple[str, str, str]
    joint_ids: tuple[int, int, int]  # Pinocchio joint indices
    q_index: int  # first of the three joints in Pinocchio's q (free-flyer q has 7 first)
    axes_B: np.ndarray  # (3, 3) unit axes
    points_B: np.ndarray  # (3, 3) joint origins
    foot_B0: np.ndarray  # (3,) foot sphere centre at zero joint angles
    foot_frame: str
    lower_rad: np.ndarray  # (3,)
    upper_rad: np.ndarray  # (3,)
    is_front: bool
    is_left: bool
    # +1: knee points forward (+x_B) of the hip-foot line, -1: rearward.
    knee_direction: int = 0


@dataclass
class Robot:
    """A 4-leg, 3-joints-per-leg quadruped read from a URDF (Pinocchio free-flyer model)."""

    name: str
    urdf_path: Path
    model: pin.Model = field(repr=False)
    legs: list[Leg]
    foot_radius_m: float
    body_box_B: np.ndarray  # (2, 3): min and max corner of the body box P in body frame
    body_box_source: str  # "urdf collision box" or how it was estimated
    total_mass_kg: float
    body_mass_kg: float
    body_com_B: np.ndarray  # (3,) COM of the root link alone
    theta_nor: np.ndarray = field(default=None)  # (4, 3) normal configuration [rad]
    reach_m: np.ndarray = field(default=None)  # (4,) max distance hip centre -> foot centre
    foot_radius_source: str = "urdf collision sphere"

    @property
    def joint_names(self) -> list[str]:
        """The 12 leg joint names, legs in order FL, FR, HL, HR."""
        return [n for leg in self.legs for n in leg.joint_names]

    @property
    def foot_frames(self) -> list[str]:
        """The URDF frames at the four foot sphere centres."""
        return [leg.foot_frame for leg in self.legs]

    @property
    def lower_rad(self) -> np.ndarray:
        """(4, 3) lower joint limits."""
        return np.array([leg.lower_rad for leg in self.legs])

    @property
    def upper_rad(self) -> np.ndarray:
        """(4, 3) upper joint limits."""
        return np.array([leg.upper_rad for leg in self.legs])

    @property
    def body_vertices_B(self) -> np.ndarray:
        """(8, 3) vertices of the body box P (paper section 4.2) in body frame."""
        lo, hi = self.body_box_B
        return np.array(
            [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        )

    def body_bottom_points_B(self, spacing_m: float = 0.02, rows: int = 3) -> np.ndarray:
        """(K, 3) points of the bottom face of P, on ``rows`` lines along x, edges included.

        Points are at most ``spacing_m`` apart along the lines. The vertices alone
        (constraint (b) of section 7.2) let a thin obstacle, a barrier or a stone edge, pass
        between them under the belly.
        """
        lo, hi = self.body_box_B
        nx = max(2, int(np.ceil((hi[0] - lo[0]) / spacing_m)) + 1)
        ny = max(2, int(rows))
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], nx), np.linspace(lo[1], hi[1], ny))
        return np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, lo[2])])

    @property
    def body_clearance_points_B(self) -> np.ndarray:
        """Points of P kept delta_c above the terrain: its 8 vertices and bottom-face grid."""
        pts = getattr(self, "_clearance_points_B", None)
        if pts is None:
            pts = np.unique(np.vstack([self.body_vertices_B, self.body_bottom_points_B()]), axis=0)
            self._clearance_points_B = pts
        return pts

    def fingerprint(self) -> str:
        """A digest of the model: Pinocchio's serialised model and every field read from it.

        Two robots with the same fingerprint have the same kinematics, inertia, limits,
        feet and body box, so the problems built for one serve the other
        (:mod:`planner.problems.cache`).
        """
        digest = hashlib.sha256(self.model.saveToString().encode())
        for part in [self, *self.legs]:
            for f in fields(part):
                value = getattr(part, f.name)
                if f.name in ("model", "legs"):
                    continue
                if isinstance(value, np.ndarray):
                    value = np.ascontiguousarray(value, float).tobytes()
                digest.update(f.name.encode() + repr(value).encode())
        return digest.hexdigest()

    def q_from(self, base_position_W, base_quat_xyzw, joints_rad) -> np.ndarray:
        """Pinocchio configuration q (19,) from base pose and (4, 3) or (12,) joint angles."""
        q = np.zeros(self.model.nq)
        q[:3] = base_position_W
        q[3:7] = base_quat_xyzw
        joints = np.asarray(joints_rad, dtype=float).reshape(4, 3)
        for leg in self.legs:
            q[leg.q_index : leg.q_index + 3] = joints[leg.index]
        return q

    def joints_from_q(self, q) -> np.ndarray:
        """(4, 3) leg joint angles out of a Pinocchio configuration q."""
        return np.array([q[leg.q_index : leg.q_index + 3] for leg in self.legs])
