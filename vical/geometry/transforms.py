"""Rigid transforms, rotations and their parameterisations (pure numpy).

Conventions (see ``docs/conventions.md``):

- ``T_a_b`` is a (4, 4) homogeneous matrix that maps points expressed in frame ``b`` into
  frame ``a``: ``x_a = T_a_b @ x_b``. Composition reads left to right: ``T_a_c = T_a_b @ T_b_c``.
- Quaternions are ``[w, x, y, z]`` (scalar first, as MuJoCo and GTSAM), unit norm.
- Euler angles ``[roll, pitch, yaw]`` [rad] compose as ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``
  (intrinsic Z-Y'-X'' = extrinsic X-Y-Z, the ROS/aerospace convention).
- Rotation vectors are axis * angle [rad]; ``so3_exp``/``so3_log`` map between them and matrices.
"""

from __future__ import annotations

import math

import numpy as np

_SMALL_ANGLE = 1e-8


def skew(w: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[w]_x`` of a 3-vector, so that ``skew(w) @ v == np.cross(w, v)``."""
    wx, wy, wz = np.asarray(w, dtype=float)
    return np.array([[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]])


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of the rotation vector ``w`` (3,) [rad] (Rodrigues)."""
    w = np.asarray(w, dtype=float)
    theta = float(np.linalg.norm(w))
    K = skew(w)
    if theta < _SMALL_ANGLE:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * K @ K


def so3_exp_batch(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (K, 3, 3) of rotation vectors ``w`` (K, 3) [rad]: Rodrigues'
    ``cos(theta) I + a [w]x + b w w^T`` (``a = sin(theta) / theta``, ``b = (1 - cos(theta)) / theta^2``), element by
    element (no 3 x 3 products: one per corner of a rolling shutter, ``vical.calib.solve.corner_factors``)."""
    w = np.asarray(w, dtype=float).reshape(-1, 3)
    theta, a, b = _rodrigues_coefficients(w)
    R = b[:, None, None] * w[:, :, None] * w[:, None, :]
    for i in range(3):
        R[:, i, i] += 1.0 - b * theta**2  # cos(theta)
    aw = a[:, None] * w
    R[:, 0, 1] -= aw[:, 2]
    R[:, 0, 2] += aw[:, 1]
    R[:, 1, 2] -= aw[:, 0]
    R[:, 1, 0] += aw[:, 2]
    R[:, 2, 0] -= aw[:, 1]
    R[:, 2, 1] += aw[:, 0]
    return R


def _rodrigues_coefficients(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``theta = |w|``, ``a = sin(theta) / theta`` and ``b = (1 - cos(theta)) / theta^2`` (K,) of rotation vectors
    (K, 3), their Taylor series below ``_SMALL_ANGLE``."""
    theta = np.linalg.norm(w, axis=1)
    small = theta < _SMALL_ANGLE
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    return theta, a, b


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) [rad] of the rotation matrix ``R`` (3, 3); angle in [0, pi]."""
    R = np.asarray(R, dtype=float)
    # Scalar arithmetic on Python floats: the IK calls this ~240 times per env step, and numpy's per-call
    # overhead on 3 numbers was most of its cost. Each float is the one np.trace, np.clip and
    # np.linalg.norm give (the same operations in the same order).
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    vee = np.array([r21 - r12, r02 - r20, r10 - r01])  # 2 sin(theta) axis
    cos_theta = min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0)
    theta = float(np.arctan2(0.5 * math.sqrt(vee.dot(vee)), cos_theta))  # well conditioned at 0 and pi
    if theta < 1e-6:
        return 0.5 * vee
    if np.pi - theta < 1e-4:
        # Near pi the antisymmetric part vanishes: the symmetric part is cos I + (1 - cos) a a^T.
        aaT = ((R + R.T) / 2.0 - cos_theta * np.eye(3)) / (1.0 - cos_theta)
        k = int(np.argmax(np.diag(aaT)))
        axis = aaT[:, k] / np.sqrt(aaT[k, k])
        axis /= np.linalg.norm(axis)
        if np.dot(axis, vee) < 0:
            axis = -axis
        return axis * theta
    return theta / (2.0 * np.sin(theta)) * vee


def rotation_angle(R: np.ndarray) -> float:
    """Angle [rad] of the rotation ``R`` (3, 3)."""
    return float(np.linalg.norm(so3_log(R)))


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Homogeneous (4, 4) transform from rotation ``R`` (3, 3) and translation ``t`` (3,) [m]; stacks of them
    (..., 3, 3) and (..., 3) give (..., 4, 4)."""
    R = np.asarray(R, dtype=float)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid (4, 4) transform: ``T_b_a`` from ``T_a_b``."""
    R = T[:3, :3]
    return make_transform(R.T, -R.T @ T[:3, 3])


def transform_points(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Map points ``p_b`` (N, 3) or (3,) [m] from frame b into frame a."""
    p_b = np.asarray(p_b, dtype=float)
    return p_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion ``[w, x, y, z]`` (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion ``[w, x, y, z]`` with ``w >= 0`` of the rotation matrix ``R`` (3, 3)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def euler_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) of Euler angles ``[roll, pitch, yaw]`` [rad]: ``Rz(yaw) Ry(pitch) Rx(roll)``; a stack of
    angles (..., 3) gives (..., 3, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    c, s = np.cos(rpy), np.sin(rpy)
    zero, one = np.zeros(rpy.shape[:-1]), np.ones(rpy.shape[:-1])

    def matrix(rows: list[list[np.ndarray]]) -> np.ndarray:
        return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)

    (cr, cp, cy), (sr, sp, sy) = np.moveaxis(c, -1, 0), np.moveaxis(s, -1, 0)
    Rx = matrix([[one, zero, zero], [zero, cr, -sr], [zero, sr, cr]])
    Ry = matrix([[cp, zero, sp], [zero, one, zero], [-sp, zero, cp]])
    Rz = matrix([[cy, -sy, zero], [sy, cy, zero], [zero, zero, one]])
    return Rz @ Ry @ Rx


def matrix_to_euler(R: np.ndarray) -> np.ndarray:
    """Euler angles ``[roll, pitch, yaw]`` [rad] of ``R`` (3, 3), inverse of ``euler_to_matrix``.

    Pitch is in [-pi/2, pi/2]; at gimbal lock (|pitch| = pi/2) roll is set to 0.
    """
    R = np.asarray(R, dtype=float)
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    if abs(R[2, 0]) > 1.0 - 1e-12:
        return np.array([0.0, pitch, np.arctan2(-R[0, 1], R[1, 1])])
    return np.array([np.arctan2(R[2, 1], R[2, 2]), pitch, np.arctan2(R[1, 0], R[0, 0])])


def step_pose(T: np.ndarray, translation: np.ndarray, euler_increment: np.ndarray) -> np.ndarray:
    """Pose ``T`` (4, 4) moved by ``translation`` (3,) [m] (world axes) with its Euler angles
    ``[roll, pitch, yaw]`` (world-fixed, see ``euler_to_matrix``) increased by ``euler_increment`` (3,) [rad]."""
    euler = matrix_to_euler(T[:3, :3]) + np.asarray(euler_increment, dtype=float)
    return make_transform(euler_to_matrix(euler), T[:3, 3] + np.asarray(translation, dtype=float))


def slerp_rotation(R0: np.ndarray, R1: np.ndarray, s: float) -> np.ndarray:
    """Geodesic interpolation between rotations: ``R0 @ exp(s * log(R0^T R1))``, ``s`` in [0, 1]."""
    return R0 @ so3_exp(s * so3_log(R0.T @ R1))


def interpolate_transforms(t: np.ndarray, T: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Poses (K, 4, 4) at times ``query`` (K,) between the poses ``T`` (M, 4, 4) at increasing times ``t`` (M,),
    as ``interpolate_transform`` between the two around each (held at the ends)."""
    t, query = np.asarray(t, dtype=float), np.asarray(query, dtype=float)
    if len(t) == 1:
        return np.repeat(np.asarray(T, dtype=float)[:1], len(query), axis=0)
    after = np.clip(np.searchsorted(t, query, side="right"), 1, len(t) - 1)
    s = np.clip((query - t[after - 1]) / (t[after] - t[after - 1]), 0.0, 1.0)
    steps = np.array([so3_log(T[j - 1, :3, :3].T @ T[j, :3, :3]) for j in range(1, len(t))])  # (M - 1, 3)
    out = np.zeros((len(query), 4, 4))
    out[:, :3, :3] = T[after - 1, :3, :3] @ so3_exp_batch(s[:, None] * steps[after - 1])
    out[:, :3, 3] = (1.0 - s)[:, None] * T[after - 1, :3, 3] + s[:, None] * T[after, :3, 3]
    out[:, 3, 3] = 1.0
    return out


def interpolate_transform(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose between ``T0`` and ``T1``: linear in translation, geodesic in rotation (``s`` in [0, 1])."""
    R = slerp_rotation(T0[:3, :3], T1[:3, :3], s)
    t = (1.0 - s) * T0[:3, 3] + s * T1[:3, 3]
    return make_transform(R, t)


def transform_error(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """Rotation error [rad] and translation error [m] between two (4, 4) transforms."""
    dR = T_est[:3, :3].T @ T_ref[:3, :3]
    return rotation_angle(dR), float(np.linalg.norm(T_est[:3, 3] - T_ref[:3, 3]))
