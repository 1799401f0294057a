"""Compact exponential coordinates on SE(3) and SO(3) helpers.

The paper (section 4.7) writes a pose ``g = (R, v)`` in SE(3) as the 6-vector
``eps(g) = [v; theta*omega]``: the translation ``v`` is kept *as is* (unlike the
twist coordinates of Murray, Li & Sastry, ch. 2), and ``theta*omega`` is the
rotation vector (axis-angle) of ``R`` with ``theta`` in ``[0, pi]``.  The inverse
map is ``g~(eps)``.  Section 7.1 (eqs. 6a/6b) interpolates poses linearly in
these coordinates, see :func:`interpolate_coords`.

Everything is provided in numpy; the exponential map is also provided for
CasADi (SX/MX) with a smooth Taylor branch at ``theta = 0`` so that its
derivatives are finite and exact there.  Quaternions use pinocchio's
``(x, y, z, w)`` order.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "hat",
    "vee",
    "hat_ca",
    "rotation_from_vector",
    "rotation_from_vector_ca",
    "vector_from_rotation",
    "vector_from_rotation_ca",
    "pose_from_coords",
    "pose_from_coords_ca",
    "coords_from_pose",
    "interpolate_coords",
    "quat_from_rotation",
    "rotation_from_quat",
]

# Below this squared angle the Taylor series of the Rodrigues coefficients is used.
# Series truncated after the theta^8 term: remainder < theta^10 / 10! ~ 3e-27 here.
_TAYLOR_T2 = 1e-4
_Array = NDArray[np.float64]


def hat(w: ArrayLike) -> _Array:
    """Return the skew-symmetric matrix of a 3-vector, ``hat(w) @ x == cross(w, x)`` (MLS 2.2)."""
    x, y, z = np.asarray(w, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def vee(W: ArrayLike) -> _Array:
    """Inverse of :func:`hat`: the 3-vector of the skew part of a 3x3 matrix."""
    W = np.asarray(W, dtype=float)
    return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])


def hat_ca(w: ca.SX | ca.MX | ca.DM) -> ca.SX | ca.MX | ca.DM:
    """CasADi version of :func:`hat` for a 3x1 symbolic vector."""
    z = 0 * w[0]
    return ca.vertcat(
        ca.horzcat(z, -w[2], w[1]),
        ca.horzcat(w[2], z, -w[0]),
        ca.horzcat(-w[1], w[0], z),
    )


def _rodrigues_coeffs(t2: float) -> tuple[float, float]:
    """Return ``(sin t / t, (1 - cos t) / t^2)`` for ``t2 = t^2`` (series near 0)."""
    if t2 < _TAYLOR_T2:
        a = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0)))
        b = 0.5 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0))))
        return a, b
    t = np.sqrt(t2)
    s = np.sin(0.5 * t)
    return np.sin(t) / t, 2.0 * s * s / t2


def rotation_from_vector(phi: ArrayLike) -> _Array:
    """Exponential map so(3) -> SO(3) (Rodrigues' formula, MLS eq. 2.14).

    Parameters
    ----------
    phi : array_like, shape (3,)
        Rotation vector ``theta * omega``.

    Returns
    -------
    ndarray, shape (3, 3)
        ``exp(hat(phi)) = I + sin(t)/t K + (1 - cos t)/t^2 K^2`` with ``K = hat(phi)``;
        the coefficients switch to their Taylor series for ``t^2 < 1e-4``.

    """
    phi = np.asarray(phi, dtype=float).reshape(3)
    a, b = _rodrigues_coeffs(float(phi @ phi))
    K = hat(phi)
    return np.eye(3) + a * K + b * (K @ K)


def rotation_from_vector_ca(phi: ca.SX | ca.MX | ca.DM) -> ca.SX | ca.MX | ca.DM:
    """CasADi Rodrigues formula, smooth with exact derivatives at ``phi = 0``.

    Uses ``if_else`` on ``t^2 < 1e-4`` between the Taylor series (a polynomial in
    ``t^2``, no ``sqrt``) and the closed form evaluated at a *safe* ``t^2`` (forced to
    1 inside the Taylor region), so neither branch produces inf/NaN in forward or
    reverse mode differentiation.

    Parameters
    ----------
    phi : casadi SX/MX/DM, shape (3, 1)
        Rotation vector.

    Returns
    -------
    casadi SX/MX/DM, shape (3, 3)
        The rotation matrix ``exp(hat(phi))``.

    """
    t2 = ca.dot(phi, phi)
    small = t2 < _TAYLOR_T2
    a_ser = 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72)))
    b_ser = 0.5 * (1 - t2 / 12 * (1 - t2 / 30 * (1 - t2 / 56 * (1 - t2 / 90))))
    t2s = ca.if_else(small, 1.0, t2)
    ts = ca.sqrt(t2s)
    sh = ca.sin(0.5 * ts)
    a = ca.if_else(small, a_ser, ca.sin(ts) / ts)
    b = ca.if_else(small, b_ser, 2 * sh * sh / t2s)
    K = hat_ca(phi)
    return ca.DM.eye(3) + a * K + b * ca.mtimes(K, K)


def vector_from_rotation(R: ArrayLike) -> _Array:
    """Logarithm map SO(3) -> so(3): rotation vector ``theta*omega``, ``theta in [0, pi]``.

    The angle is ``atan2(|w|, (tr R - 1)/2)`` with ``w = vee(R - R^T)/2 = sin(theta)
    omega``, accurate over the whole range.  For ``theta <= pi/2`` the axis is
    ``w / |w|`` (series for ``theta/sin(theta)`` near 0).  For ``theta > pi/2`` it is
    read off the symmetric part ``(R + R^T)/2 - cos(theta) I = (1 - cos theta)
    omega omega^T`` (column of the largest diagonal entry), its sign fixed by ``w``;
    this keeps full double precision up to ``theta = pi`` where ``w`` vanishes.  At
    exactly ``theta = pi`` either of ``+-pi*omega`` may be returned.

    Parameters
    ----------
    R : array_like, shape (3, 3)
        Rotation matrix.

    Returns
    -------
    ndarray, shape (3,)
        Rotation vector with norm in ``[0, pi]``.

    """
    R = np.asarray(R, dtype=float)
    w = vee(R)
    s = float(np.linalg.norm(w))
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = float(np.arctan2(s, c))
    if c >= 0.0:
        if s < 1e-8:  # theta/sin(theta) = 1 + s^2/6 + 3 s^4/40 + ...
            return (1.0 + s * s / 6.0) * w
        return (theta / s) * w
    S = 0.5 * (R + R.T) - c * np.eye(3)  # = (1 - c) omega omega^T
    k = int(np.argmax(np.diag(S)))
    axis = S[:, k] / np.linalg.norm(S[:, k])
    if axis @ w < 0.0:
        axis = -axis
    return theta * axis


def vector_from_rotation_ca(R: ca.SX | ca.MX | ca.DM) -> ca.SX | ca.MX | ca.DM:
    """:func:`vector_from_rotation` in CasADi for rotations below pi: theta / sin(theta) v.

    v is the axial vector of R's skew part; its series 1 + theta^2 / 6 is taken near
    theta = 0, where the expression and its derivatives stay smooth.
    """
    v = 0.5 * ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    s2 = ca.dot(v, v)
    f = ca.if_else(s2 < 1e-8, 1.0 + s2 / 6.0, ca.atan2(ca.sqrt(s2), c) / ca.sqrt(s2), True)
    return f * v


def pose_from_coords(eps: ArrayLike) -> _Array:
    """Inverse compact exponential coordinates ``g~(eps)`` (paper section 4.7).

    Parameters
    ----------
    eps : array_like, shape (6,)
        ``[v; theta*omega]``: translation then rotation vector.

    Returns
    -------
    ndarray, shape (4, 4)
        Homogeneous transform ``[[R, v], [0, 1]]``.

    """
    eps = np.asarray(eps, dtype=float).reshape(6)
    T = np.eye(4)
    T[:3, :3] = rotation_from_vector(eps[3:])
    T[:3, 3] = eps[:3]
    return T


def pose_from_coords_ca(
    eps: ca.SX | ca.MX | ca.DM,
) -> tuple[ca.SX | ca.MX | ca.DM, ca.SX | ca.MX | ca.DM]:
    """CasADi version of :func:`pose_from_coords`.

    Parameters
    ----------
    eps : casadi SX/MX/DM, shape (6, 1)
        ``[v; theta*omega]``.

    Returns
    -------
    R : casadi, shape (3, 3)
        Rotation, smooth in ``eps`` (see :func:`rotation_from_vector_ca`).
    p : casadi, shape (3, 1)
        Translation ``eps[0:3]``.

    """
    return rotation_from_vector_ca(eps[3:6]), eps[0:3]


def coords_from_pose(T: ArrayLike) -> _Array:
    """Compact exponential coordinates ``eps~(g) = [v; theta*omega]`` (paper section 4.7).

    Parameters
    ----------
    T : array_like, shape (4, 4) or (3, 4)
        Homogeneous transform; only the top three rows are read.

    Returns
    -------
    ndarray, shape (6,)
        Translation followed by the rotation vector (:func:`vector_from_rotation`).

    """
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[:3, 3], vector_from_rotation(T[:3, :3])])


def interpolate_coords(eps1: ArrayLike, eps2: ArrayLike, nu: ArrayLike) -> _Array:
    """Linear interpolation in compact exponential coordinates (paper eqs. 6a/6b).

    Returns ``(1 - nu) eps1 + nu eps2``.  The rotation vectors are first made
    consistent: if ``|phi2 - phi1| > pi``, ``phi2`` is replaced by the equivalent
    vector ``phi2 - 2 pi phi2/|phi2|`` (same rotation, angle ``theta2 - 2 pi``) when
    that brings it closer to ``phi1``, so the interpolation turns the short way
    (e.g. across ``theta = pi``).  Interpolated rotation vectors may then have norm
    above ``pi``; they are still valid inputs of :func:`pose_from_coords`.

    Parameters
    ----------
    eps1, eps2 : array_like, shape (6,)
        End points, ``nu = 0`` and ``nu = 1``.
    nu : float or array_like, shape (N,)
        Interpolation parameter(s) in ``[0, 1]``.

    Returns
    -------
    ndarray, shape (6,) or (N, 6)
        Interpolated coordinates (one row per ``nu`` when ``nu`` is an array).

    """
    e1 = np.asarray(eps1, dtype=float).reshape(6)
    e2 = np.asarray(eps2, dtype=float).reshape(6).copy()
    phi1, phi2 = e1[3:], e2[3:]
    n2 = float(np.linalg.norm(phi2))
    if n2 > 0.0 and np.linalg.norm(phi2 - phi1) > np.pi:
        alt = phi2 - (2.0 * np.pi / n2) * phi2
        if np.linalg.norm(alt - phi1) < np.linalg.norm(phi2 - phi1):
            e2[3:] = alt
    nu_arr = np.asarray(nu, dtype=float)
    if nu_arr.ndim == 0:
        return (1.0 - nu_arr) * e1 + nu_arr * e2
    nu_col = nu_arr.reshape(-1, 1)
    return (1.0 - nu_col) * e1 + nu_col * e2


def quat_from_rotation(R: ArrayLike) -> _Array:
    """Return the unit quaternion ``(x, y, z, w)`` of a rotation matrix, ``w >= 0``.

    Uses ``pinocchio.Quaternion`` (Shepperd's method); the sign is chosen so that
    ``w >= 0``.
    """
    q = np.array(pin.Quaternion(np.asarray(R, dtype=float)).coeffs(), dtype=float)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0.0 else q


def rotation_from_quat(q: ArrayLike) -> _Array:
    """Return the rotation matrix of a quaternion ``(x, y, z, w)`` (normalised first)."""
    x, y, z, w = np.asarray(q, dtype=float).reshape(4) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
