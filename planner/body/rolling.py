"""Rolling sphere feet: the leaves of the strata as the physics has them (sections 4.3, 7.1).

The paper's leaves keep each stance foot's contact point fixed. A LittleDog foot is a
rigid sphere (radius rho) fixed to the shank, and a foot that does not *slide* must
*roll*: when the shank turns by the rotation vector w (world frame), the material point
touching the ground stays still, so the sphere centre moves by

    delta_c = rho w x n                                   (n: terrain normal at the contact)

and the contact point moves with it along the surface. Measured in MuJoCo on plans with
fixed contact points (section 10, the executor's sliding metric): a stance foot's centre
travelled 2-4 mm per body move while its contact point slid < 0.5 mm, and open-loop walks
ended 6 cm per metre from their planned end (the plan's joints were solved for fixed
centres that the real feet did not keep). Holding the contact point still instead
(rolling friction, a torsional stop) is not what a rubber ball on a shank does, so the
planner models rolling.

*Sliding* is what no-slip forbids, and one definition serves the planner, the validator
and the simulator: the tangential part of the centre's travel minus the rolling,

    sliding = P_n (delta_c - rho w x n),   P_n = I - n n^T,

per pair of consecutive samples in :func:`planner.planfile.validate.check_plan` (``stance_slip``,
rotations from Pinocchio) and integrated over time in :class:`planner.sim.monitor.Monitor`
(velocity of the sphere's material point at the contact). The normal part is whether the
sphere still rests on the terrain (``foot_on_terrain``).

:func:`roll_stance_feet` moves the stance feet of one interpolation sample
(:mod:`planner.motion.interpolate`): the shank rotation depends on the joints, the joints on the
centres (IK), so the two are iterated to a fixed point (contraction ~rho / leg length).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from planner.body.contact import TerrainLike

if TYPE_CHECKING:
    from planner.body.kinematics import LegKinematics

__all__ = [
    "end_keyframe",
    "leg_rotations_W",
    "leg_rotations_W_ca",
    "rolled_centres_W",
    "rolled_centres_W_ca",
    "roll_stance_feet",
    "rolling_displacement",
    "sliding",
]

_Array = NDArray[np.float64]
FIXED_POINT_ITERATIONS = 8  # error x (rho / leg length)^k per iteration (0.06^k, LittleDog)
CONVERGED_M = 1e-7  # centre change [m] that ends the iteration (check's slip limit: 1e-6)
REST_ITERATIONS = 4  # Newton steps putting a rolled centre back on the offset surface
REST_TOL_M = 1e-10  # gap [m] that ends them (check's slip and surface tolerances: 1e-6)


def leg_rotations_W(kin: LegKinematics, base_rotation_W: _Array, joints_rad: _Array) -> _Array:
    """(4, 3, 3) world orientation of each shank (up to its constant zero-pose rotation).

    Product of exponentials (eq. 1) of the leg's joint axes (body frame, zero pose) times
    the base rotation; only relative rotations are used, so the constant cancels.
    """
    k, k2 = _axis_hats(kin)
    jr = np.asarray(joints_rad, float).reshape(4, 3)
    s, c = np.sin(jr)[..., None, None], np.cos(jr)[..., None, None]
    e = np.eye(3) + s * k + (1.0 - c) * k2  # (4, 3, 3, 3): Rodrigues, every joint at once
    return np.asarray(base_rotation_W, float) @ e[:, 0] @ e[:, 1] @ e[:, 2]


def leg_rotations_W_ca(kin: LegKinematics, base_rotation_W, joints12) -> list:
    """:func:`leg_rotations_W` in CasADi: four symbolic (3, 3) shank orientations."""
    import casadi as ca

    from planner.body.kinematics import axis_rotation_ca

    out = []
    for i, leg in enumerate(kin.legs):
        R = base_rotation_W
        for j in range(3):
            axis = np.asarray(leg.axes_B[j], float)
            R = ca.mtimes(R, axis_rotation_ca(axis, joints12[3 * i + j]))
        out.append(R)
    return out


def rolled_centres_W(
    kin: LegKinematics, base_rotation_W, joints_rad, centres_W, rotations_W, normals_W
) -> _Array:
    """(4, 3) sphere centres rolled from ``centres_W`` as the shanks turn to ``joints_rad``.

    ``rotations_W`` (4, 3, 3): the shanks' orientations where the centres were
    (:func:`leg_rotations_W`); ``normals_W`` (4, 3): the terrain normals there. One rigid
    roll per foot, c + rho w x n (module docstring): the end of a body move's rolling to
    second order in its shank rotations (on a plane exactly, for a rotation about one axis).
    """
    R_now = leg_rotations_W(kin, base_rotation_W, joints_rad)
    c = np.asarray(centres_W, float).reshape(4, 3)
    return c + rolling_displacement(rotations_W, R_now, normals_W, kin.robot.foot_radius_m)


def rolled_centres_W_ca(
    kin: LegKinematics, base_rotation_W, joints12, centres_cols, normals_cols, rotations_cols
):
    """:func:`rolled_centres_W` in CasADi: a (3, 4) expression of the body pose and joints.

    ``rotations_cols`` (9, 4): each shank's start orientation, column-major; w by
    :func:`planner.core.lie.vector_from_rotation_ca`.
    """
    import casadi as ca

    from planner.core.lie import vector_from_rotation_ca

    rho = float(kin.robot.foot_radius_m)
    cols = []
    for i, R_now in enumerate(leg_rotations_W_ca(kin, base_rotation_W, joints12)):
        w = vector_from_rotation_ca(ca.mtimes(R_now, ca.reshape(rotations_cols[:, i], 3, 3).T))
        cols.append(centres_cols[:, i] + rho * ca.cross(w, normals_cols[:, i]))
    return ca.horzcat(*cols)


def _axis_hats(kin: LegKinematics) -> tuple[_Array, _Array]:
    """(4, 3, 3, 3) skew matrices of the joint axes and their squares, cached on ``kin``."""
    cached = getattr(kin, "_rolling_axis_hats", None)
    if cached is None:
        a = np.array([leg.axes_B for leg in kin.legs], float)  # (4, 3, 3): leg, joint, xyz
        k = np.zeros(a.shape[:2] + (3, 3))
        k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
        k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = a[..., 2], -a[..., 1], a[..., 0]
        cached = (k, k @ k)
        kin._rolling_axis_hats = cached
    return cached


def rolling_displacement(R_prev: _Array, R_now: _Array, normal_W: _Array, radius_m: float):
    """Centre displacement rho w x n of spheres turned from ``R_prev`` to ``R_now``.

    ``R_*`` (..., 3, 3) world orientations, ``normal_W`` (..., 3); w is the world-frame
    rotation vector of ``R_now R_prev^T``.
    """
    Rp = np.asarray(R_prev, float).reshape(-1, 3, 3)
    Rn = np.asarray(R_now, float).reshape(-1, 3, 3)
    n = np.asarray(normal_W, float).reshape(-1, 3)
    w = np.array([np.asarray(pin.log3(a @ b.T)) for a, b in zip(Rn, Rp, strict=True)])
    return float(radius_m) * np.cross(w, n)


def sliding(c_prev, c_now, R_prev, R_now, normal_W, radius_m: float) -> _Array:
    """(N,) sliding [m] of stance feet between two samples: |P_n (delta_c - rho w x n)|."""
    n = np.asarray(normal_W, float).reshape(-1, 3)
    d = np.asarray(c_now, float).reshape(-1, 3) - np.asarray(c_prev, float).reshape(-1, 3)
    res = d - rolling_displacement(R_prev, R_now, n, radius_m)
    res = res - np.sum(res * n, axis=1, keepdims=True) * n
    return np.linalg.norm(res, axis=1)


def _rest(
    terrain: TerrainLike, c: _Array, n_dir: _Array, rho: float, n_start: _Array
) -> tuple[_Array, _Array, _Array]:
    """Move centres along ``n_dir`` until their spheres rest on the terrain.

    The contact point r = c - rho n(r) lies on the surface when the sphere rests; its
    height over the surface along the normal, f_T(r) n_z, is the gap closed by each
    Newton step. r starts from ``n_start`` (the normal of a contact nearby: the last
    one found) and takes the normal at the last r at each step, one terrain pass a step.
    Returns (centres, contacts, normals at the contacts).
    """
    c = c.copy()
    n = np.asarray(n_start, float).reshape(-1, 3)
    r = c - rho * n
    for _ in range(REST_ITERATIONS):
        f, n = _f_T_and_normal(terrain, r)
        gap = f * n[:, 2]  # > 0: above resting
        c = c - (gap / np.maximum(np.sum(n * n_dir, axis=1), 0.5))[:, None] * n_dir
        r = c - rho * n
        if float(np.max(np.abs(gap))) < REST_TOL_M:
            break
    return c, r, n


def _f_T_and_normal(terrain: TerrainLike, r: _Array) -> tuple[_Array, _Array]:
    """(f_T (N,), normals (N, 3)) at points r, in one terrain pass where the terrain has it."""
    both = getattr(terrain, "f_T_and_normal", None)
    if both is not None:
        f, n = both(r)
    else:
        f, n = terrain.f_T(r), terrain.normal(r)
    return np.asarray(f, float).reshape(-1), np.asarray(n, float).reshape(-1, 3)


def roll_stance_feet(
    kin: LegKinematics,
    terrain: TerrainLike,
    base_position_W: _Array,
    base_rotation_W: _Array,
    centres_prev_W: _Array,
    contacts_prev_W: _Array,
    rotations_prev_W: _Array,
    stance: list[int],
    centres_W: _Array,
    reference_rad: _Array,
):
    """Stance feet of the next sample, rolled from the previous one (module docstring).

    ``centres_W`` (4, 3) holds every foot's centre for this sample (swing feet as
    planned, stance feet as a first guess); ``*_prev_W`` describe the previous sample.
    Returns (centres (4, 3), contacts of the stance feet (len(stance), 3), IK results,
    leg rotations (4, 3, 3)).
    """
    rho = kin.robot.foot_radius_m
    c = np.array(centres_W, float)
    s = list(stance)
    n_prev = np.asarray(terrain.normal(contacts_prev_W[s]), float).reshape(-1, 3)
    R_W = np.asarray(base_rotation_W, float)
    p_W = np.asarray(base_position_W, float)
    ref = np.asarray(reference_rad, float).reshape(4, 3)
    c_B = (c - p_W) @ R_W
    results = [kin.ik_leg_near(i, c_B[i], ref[i]) for i in range(4)]  # swing legs once
    contacts, n_contact = None, n_prev
    for _ in range(FIXED_POINT_ITERATIONS):
        joints = np.array([r.joints_rad for r in results])
        R_now = leg_rotations_W(kin, R_W, joints)
        moved = centres_prev_W[s] + rolling_displacement(rotations_prev_W[s], R_now[s], n_prev, rho)
        # the tangential rolling leaves a sphere O(curvature x step^2) off a curved
        # terrain: put it back along n (no tangential part, so no sliding), inside the
        # fixed point so that the legs' rotations, hence the rolling, follow
        moved, contacts, n_contact = _rest(terrain, moved, n_prev, rho, n_contact)
        change = float(np.max(np.abs(moved - c[s])))
        c[s] = moved
        for i in s:  # stance legs onto their rolled centres (Newton from the last angles)
            results[i] = kin.ik_leg_near(i, (c[i] - p_W) @ R_W, results[i].joints_rad)
        if change < CONVERGED_M:
            break
    joints = np.array([r.joints_rad for r in results])
    return c, contacts, results, leg_rotations_W(kin, R_W, joints)


def end_keyframe(robot, path: list, support, com_W=None):
    """The last state of a rolled path as a keyframe: ``support`` and its eq. 5 forces.

    Along a path the stance feet roll, so the path ends on feet a few millimetres from
    the Theta solution it was interpolated to; the keyframe is that last sample, with the
    equilibrating forces (eq. 5) solved again for its feet and COM (``com_W``, default the
    whole-body COM by Pinocchio). Returns a copy; ``path`` is not changed.
    """
    from planner.body.statics import equilibrating_forces

    end = path[-1].copy()
    end.support = tuple(int(i) for i in support)
    if com_W is None:
        q = robot.q_from(end.base_position_W, end.base_quaternion_xyzw, end.joints_rad)
        com_W = np.asarray(pin.centerOfMass(robot.model, robot.model.createData(), q))
    eq = equilibrating_forces(end.feet_W, com_W, robot.total_mass_kg, end.support)
    end.forces_W = None if eq.degenerate else eq.forces
    return end
