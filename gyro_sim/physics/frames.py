"""Frames, quaternions and the Euler angles of the body in the kinetic-moment frame.

Conventions (physics.md §1):

* Case frame Z (inertial, stator housing) with unit vectors z1, z2, z3.
* Body frame X: principal axes, x3 the polar axis.
* Attitude quaternion ``q = (w, x, y, z)`` maps body to case coordinates:
  ``v_case = R(q) v_body``.
* Kinetic-moment frame Y: y3 = L/|L|; with ρ the polar angle of L from z3 and σ
  its azimuth, y1 = (cosρ cosσ, cosρ sinσ, −sinρ), y2 = (−sinσ, cosσ, 0).
* Euler angles (z-x-z) of the body in Y: R = Y Rz(ψ) Rx(θ) Rz(φ) ([M] (2.2)),
  so that L_b = |L| (sinθ sinφ, sinθ cosφ, cosθ). They are outputs only:
  singular at θ = 0, π and never integrated.

Vectorised NumPy functions take arrays with the vector index last.
"""
from __future__ import annotations

import math

import numpy as np


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3), body → case, of unit quaternions q (..., 4) = (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    if q.size == 4 and q.shape[-1] == 4:  # one quaternion (a tick's sample): scalar code, the same bits (the same
        # IEEE operations in the same order), ~2 µs instead of ~15
        return np.array(_matrix(*q.ravel().tolist())).reshape(q.shape[:-1] + (3, 3))
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def _matrix(w: float, x: float, y: float, z: float) -> tuple:
    """:func:`quat_to_matrix` of one quaternion, rows of Python floats (its expressions, term for term)."""
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) with w ≥ 0 of a single rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    cands = np.array([tr, R[0, 0], R[1, 1], R[2, 2]])
    i = int(np.argmax(cands))
    if i == 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    elif i == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s])
    elif i == 2:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    if q[0] < 0:
        q = -q
    return q / np.linalg.norm(q)


def rot_x(a: float) -> np.ndarray:
    """Rotation matrix about x by angle a (rad)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation matrix about y by angle a (rad)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation matrix about z by angle a (rad)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def l_frame(L: np.ndarray) -> np.ndarray:
    """Kinetic-moment frame Y (..., 3, 3), columns y1, y2, y3, of case-frame L (..., 3).

    Where L = 0 the frame of L ∥ z3 (Y = I) is returned; where L ∥ ±z3 the azimuth σ is 0
    (also for signed zeros, which atan2 would turn into σ = π).
    """
    L = np.asarray(L, dtype=float)
    Lx, Ly, Lz = np.moveaxis(L, -1, 0)
    h = np.hypot(Lx, Ly)
    rho = np.arctan2(h, Lz)
    sig = np.where(h > 0.0, np.arctan2(Ly, Lx), 0.0)
    cr, sr, cs, ss = np.cos(rho), np.sin(rho), np.cos(sig), np.sin(sig)
    Y = np.empty(L.shape[:-1] + (3, 3))
    Y[..., 0, 0], Y[..., 1, 0], Y[..., 2, 0] = cr * cs, cr * ss, -sr
    Y[..., 0, 1], Y[..., 1, 1], Y[..., 2, 1] = -ss, cs, 0.0
    Y[..., 0, 2], Y[..., 1, 2], Y[..., 2, 2] = sr * cs, sr * ss, cr
    return Y


def euler_angles(R: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Euler angles (..., 3) = (ψ, θ, φ) in rad of the body (R body → case) in the L-frame.

    M = Yᵀ R = Rz(ψ) Rx(θ) Rz(φ): θ = atan2(√(M13² + M23²), M33), ψ = atan2(M13, −M23),
    φ = atan2(M31, M32). ψ and φ are meaningless where θ = 0 or π.
    """
    Y = l_frame(L)
    M = np.swapaxes(Y, -1, -2) @ R
    theta = np.arctan2(np.hypot(M[..., 0, 2], M[..., 1, 2]), M[..., 2, 2])
    psi = np.arctan2(M[..., 0, 2], -M[..., 1, 2])
    phi = np.arctan2(M[..., 2, 0], M[..., 2, 1])
    return np.stack([psi, theta, phi], axis=-1)


def attitude_from_euler(L_direction: np.ndarray, psi: float, theta: float, phi: float) -> np.ndarray:
    """Quaternion (body → case) of the body at Euler angles (ψ, θ, φ) in the L-frame of a direction."""
    Y = l_frame(np.asarray(L_direction, dtype=float))
    return matrix_to_quat(Y @ rot_z(psi) @ rot_x(theta) @ rot_z(phi))


def nutation_angle(q: np.ndarray, L: np.ndarray) -> float:
    """θ (rad, 0…π): the angle between the body's polar axis x3 (q = (w, x, y, z): body → case) and L (case
    frame); 0 for L = 0. Scalar code (a region test calls it at every check)."""
    w, x, y, z = (float(v) for v in q)
    return _angle_one(_column(w, x, y, z, 2), tuple(float(v) for v in L))  # (x3 in the case frame; atan2(0, 0) = 0)


def symmetry_axis(J) -> int:
    """Index (0, 1, 2) of the body's symmetry axis from principal moments J (kg m²): the axis whose moment differs
    where two are equal (2 for an isotropic body: x3), −1 for a triaxial body (no symmetry axis)."""
    J0, J1, J2 = (float(v) for v in J)
    if J0 == J1:
        return 2
    if J1 == J2:
        return 0
    if J0 == J2:
        return 1
    return -1


def attitude_split(q1: np.ndarray, q2: np.ndarray, axis: int, L1=None, L2=None) -> tuple[np.ndarray, np.ndarray]:
    """Split the difference of two attitudes (unit quaternions (..., 4), body → case) into what an engineer
    observes from the case and the fast phases: ``(direction, phase)`` in rad.

    Without L (``L1``/``L2`` None): ``direction`` is the angle between the body's symmetry axis x_axis in the two
    attitudes and ``phase`` the twist about that axis of the relative rotation q1⁻¹ ⊗ q2 (swing–twist).

    With the kinetic moments L1, L2 (case frame, (..., 3)), the symmetry axis is seen as the rotor shows it: a
    cone about L. ``direction`` = the angle between L1 and L2 plus the difference of the nutation angles θ (the
    cone's axis and half-angle); ``phase`` = the larger of the spin phase's error (the twist) and the arc the axis
    is off along its cone (sin θ times the precession phase's error: the angle between the two axes' projections
    on the plane normal to L): both move with phases the rotor turns through at about its spin rate.

    ``axis`` −1 (no symmetry axis): ``direction`` is the whole rotation angle between them and ``phase`` 0."""
    q1 = np.asarray(q1, dtype=float)
    q2 = np.asarray(q2, dtype=float)
    w1, v1 = q1[..., 0], q1[..., 1:]
    w2, v2 = q2[..., 0], q2[..., 1:]
    # relative rotation r = q1⁻¹ ⊗ q2 in the body frame
    w = w1 * w2 + np.sum(v1 * v2, axis=-1)
    v = w1[..., None] * v2 - w2[..., None] * v1 - np.cross(v1, v2)
    if axis < 0:
        whole = 2.0 * np.arctan2(np.linalg.norm(v, axis=-1), np.abs(w))
        return whole, np.zeros_like(whole)
    va = v[..., axis]
    twist = 2.0 * np.arctan2(va, w)
    twist = np.abs((twist + np.pi) % (2.0 * np.pi) - np.pi)
    if L1 is None or L2 is None:
        # the swing's angle is the angle between the axis and its image
        swing_s = np.sqrt(np.maximum(np.sum(v * v, axis=-1) - va * va, 0.0))
        swing = 2.0 * np.arctan2(swing_s, np.sqrt(w * w + va * va))
        return swing, twist
    a1 = quat_to_matrix(q1)[..., :, axis]
    a2 = quat_to_matrix(q2)[..., :, axis]
    L1 = np.asarray(L1, dtype=float)
    L2 = np.asarray(L2, dtype=float)
    dL = _angle(L1, L2)
    th1, th2 = _angle(a1, L1), _angle(a2, L2)
    l2 = L2 / np.maximum(np.linalg.norm(L2, axis=-1, keepdims=True), 1e-300)
    u1 = a1 - np.sum(a1 * l2, axis=-1, keepdims=True) * l2
    u2 = a2 - np.sum(a2 * l2, axis=-1, keepdims=True) * l2
    dpsi = _angle(u1, u2)
    return dL + np.abs(th1 - th2), np.maximum(twist, dpsi * np.abs(np.sin(th2)))


def attitude_split_one(q1, q2, axis: int, L1, L2) -> tuple[float, float]:
    """:func:`attitude_split` of one pair of states with their kinetic moments (the error control's, at each
    check: scalar arithmetic, ~50x faster than NumPy on 3-vectors). Returns (direction, phase) in rad."""
    # (the expressions of the generic code, term for term, unrolled: the same bits; NumPy arrays are read with one
    # tolist() each, their Python floats)
    w1, x1, y1, z1 = _floats(q1)
    w2, x2, y2, z2 = _floats(q2)
    # relative rotation q1⁻¹ ⊗ q2 (body frame)
    w = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
    v0 = w1 * x2 - w2 * x1 - (y1 * z2 - z1 * y2)
    v1 = w1 * y2 - w2 * y1 - (z1 * x2 - x1 * z2)
    v2 = w1 * z2 - w2 * z1 - (x1 * y2 - y1 * x2)
    if axis < 0:
        return 2.0 * math.atan2(math.sqrt(v0 * v0 + v1 * v1 + v2 * v2), abs(w)), 0.0
    twist = 2.0 * math.atan2(v0 if axis == 0 else v1 if axis == 1 else v2, w)
    twist = abs((twist + math.pi) % (2.0 * math.pi) - math.pi)
    a1, a2 = _column(w1, x1, y1, z1, axis), _column(w2, x2, y2, z2, axis)
    l1, l2 = _floats(L1), _floats(L2)
    th1, th2 = _angle_one(a1, l1), _angle_one(a2, l2)  # (the nutation angles about each L)
    m0, m1, m2 = l2
    n = max(math.sqrt(m0 * m0 + m1 * m1 + m2 * m2), 1e-300)
    e0, e1, e2 = m0 / n, m1 / n, m2 / n
    # (the dot products as sum() takes them in Python 3.11: a float sum from 0.0, in order)
    d1 = 0.0 + a1[0] * e0 + a1[1] * e1 + a1[2] * e2
    d2 = 0.0 + a2[0] * e0 + a2[1] * e1 + a2[2] * e2
    u1 = (a1[0] - d1 * e0, a1[1] - d1 * e1, a1[2] - d1 * e2)
    u2 = (a2[0] - d2 * e0, a2[1] - d2 * e1, a2[2] - d2 * e2)
    return _angle_one(l1, l2) + abs(th1 - th2), max(twist, _angle_one(u1, u2) * abs(math.sin(th2)))


def _floats(v) -> list:
    """The Python floats of a short vector: one tolist() of a float64 array, else float() of each element."""
    t = type(v)
    if t is list and all(type(x) is float for x in v):
        return v
    if t is np.ndarray and v.dtype == np.float64:
        return v.tolist()
    return [float(x) for x in v]


def norm3(v: np.ndarray) -> float:
    """|v| of a 3-vector as np.linalg.norm takes it (the square root of its dot product: the same bits), without
    its overhead (a few µs a call: the step plan and the error control ask at every segment and check)."""
    return math.sqrt(float(v.dot(v)))


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b row by row for (k, 3) arrays (k ≥ 0): np.cross's numbers (each component a product less a product, as
    it takes them: the same bits) in scalar code, without its ~30 µs of array plumbing (a run's start asks for the
    stators' axes e1 × e2)."""
    out = [(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
           for (a0, a1, a2), (b0, b1, b2) in zip(np.asarray(a, float).tolist(), np.asarray(b, float).tolist(),
                                                strict=True)]
    return np.array(out, dtype=float).reshape(-1, 3)


def _column(w: float, x: float, y: float, z: float, axis: int) -> tuple[float, float, float]:
    """Column ``axis`` of :func:`quat_to_matrix` of one quaternion: the body axis in the case frame."""
    if axis == 0:
        return 1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)
    if axis == 1:
        return 2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)
    return 2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)


def _angle_one(a, b) -> float:
    """The angle (rad, 0…π) between two 3-vectors (0 where either is zero): :func:`_angle` of one pair."""
    c = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    return math.atan2(math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle (rad, 0…π) between vectors a and b (..., 3), row by row (0 where either is zero)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
