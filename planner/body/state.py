"""Configurations Psi = {g, r_1..r_4} and the strata S0..S4 (paper sections 1.1, 4.1, 4.3).

A :class:`State` is a point of the 18-dimensional workspace W: the base pose g in SE(3)
(body frame origin and rotation, world frame) and the four foot contact points r_i (world
frame). Leg joint angles are carried along because they are what a robot executes; they
are tied to g and r_i by the kinematics (a foot's sphere centre is r_i + rho n_i).

Stratum ``0`` has all four feet down; stratum ``i`` (1..4, leg FL=1 .. HR=4) has leg i in
the air. Moving along a leaf means the stance feet's r_i do not change.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from planner.core.lie import coords_from_pose, quat_from_rotation

S0 = 0  # all four feet on the terrain


def stratum_name(stratum: int) -> str:
    """'S0' or 'S3 (HL up)'."""
    from planner.body.robot import LEG_NAMES

    if stratum == 0:
        return "S0"
    return f"S{stratum} ({LEG_NAMES[stratum - 1]} up)"


def contact_mask(stratum: int) -> np.ndarray:
    """(4,) booleans: which feet touch the terrain on a stratum."""
    if stratum not in range(5):
        raise ValueError(f"stratum must be 0..4, got {stratum!r}")
    mask = np.ones(4, dtype=bool)
    if stratum:
        mask[stratum - 1] = False
    return mask


@dataclass
class State:
    """A configuration Psi with its joint angles.

    Attributes
    ----------
    base_position_W : (3,) body frame origin [m], world frame.
    base_rotation_W : (3, 3) rotation body -> world.
    feet_W : (4, 3) foot contact points r_i [m], world frame (for a swing foot: the point
        a radius below its sphere centre).
    joints_rad : (4, 3) leg joint angles, legs FL, FR, HL, HR.
    stratum : 0..4.
    support : legs (0-based) taken to carry the weight, for the forces of eq. 5.

    """

    base_position_W: np.ndarray
    base_rotation_W: np.ndarray
    feet_W: np.ndarray
    joints_rad: np.ndarray
    stratum: int = S0
    support: tuple[int, ...] = (0, 1, 2, 3)
    forces_W: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.base_position_W = np.asarray(self.base_position_W, dtype=float).reshape(3)
        self.base_rotation_W = np.asarray(self.base_rotation_W, dtype=float).reshape(3, 3)
        self.feet_W = np.asarray(self.feet_W, dtype=float).reshape(4, 3)
        self.joints_rad = np.asarray(self.joints_rad, dtype=float).reshape(4, 3)
        self.support = tuple(int(i) for i in self.support)

    @property
    def in_contact(self) -> np.ndarray:
        """(4,) booleans: feet on the terrain in this stratum."""
        return contact_mask(self.stratum)

    @property
    def coords(self) -> np.ndarray:
        """Compact exponential coordinates eps(g) (section 4.7)."""
        return coords_from_pose(self.pose)

    @property
    def pose(self) -> np.ndarray:
        """4x4 homogeneous base-to-world transform g."""
        g = np.eye(4)
        g[:3, :3] = self.base_rotation_W
        g[:3, 3] = self.base_position_W
        return g

    @property
    def base_quaternion_xyzw(self) -> np.ndarray:
        """Base orientation as a unit quaternion (x, y, z, w)."""
        return quat_from_rotation(self.base_rotation_W)

    def copy(self) -> State:
        """Deep copy."""
        return replace(
            self,
            base_position_W=self.base_position_W.copy(),
            base_rotation_W=self.base_rotation_W.copy(),
            feet_W=self.feet_W.copy(),
            joints_rad=self.joints_rad.copy(),
            forces_W=None if self.forces_W is None else self.forces_W.copy(),
            info=dict(self.info),
        )
