"""Corner factors: every corner's projection in one vectorised pass, one GTSAM factor per frame.

The target's points are known, so they are constants of the factors, not variables. (Points as
variables pinned by priors connect every frame to every other through them: eliminating them makes
the whole problem one dense clique, which made real-size recordings take tens of seconds and GBs.)

Frame ``n`` sees the target from the camera pose (target frame)::

    C_n = X_n * Exp([omega_n; R_n^T v_n] * delta) * E

- ``X_n``: ``Pose3`` key of the frame's state (the IMU pose ``T_target_imu`` at the state time; in the
  intrinsic graph the camera pose ``T_target_cam`` itself, with ``E`` the identity);
- ``v_n``: ``Vector3`` key [m/s] (target frame) and ``omega_n`` [rad/s] the bias-corrected gyro rate
  at the state time (a constant), with ``delta``, a ``Vector1`` key [s], the time-offset correction:
  the pose at the exposure instant to first order in ``delta`` (the neglected ``0.5 a delta^2`` is
  5 um at 1 ms);
- ``E``: ``Pose3`` key of ``T_imu_cam``;
- the camera: a vector key of the camera's ``parameters`` (``[fx, fy, cx, cy, *coefficients]``, 8 or 6)
  or a fixed ``CameraModel``.

Each frame's factor is a ``gtsam.CustomFactor`` whose residual is ``(predicted - measured) / sigma``
for its corners (2 per corner, whitened; an optional Huber kernel per corner). GTSAM calls the
factors one by one; the first call for a set of values computes all frames at once (one numpy
pass), and each call returns its frame's slice, after checking that its variables are exactly
those the pass used. Jacobians are analytic (``CameraModel.project_jacobians``, right
perturbations of the poses as GTSAM's ``Pose3`` retraction). Camera parameters outside their model's
range (a Levenberg-Marquardt trial step, say) give non-finite residuals, which the solver rejects.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from vical.calib.solve.observations import FrameObservation
from vical.geometry import CameraModel, CameraModelError, skew


@dataclass(frozen=True)
class CornerKeys:
    """The variables the corner factors read (None: not in the graph).

    Attributes:
        poses: (F,) ``Pose3`` keys ``X_n``, one per frame.
        velocities: (F,) ``Vector3`` keys ``v_n``; needed with ``delta``.
        omegas: (F, 3) [rad/s] gyro rates at the state times; needed with ``delta``.
        extrinsic: ``Pose3`` key of ``T_imu_cam``.
        delta: ``Vector1`` key [s] of the time-offset correction.
        camera: vector key of the camera parameters (``CameraModel.parameters``).
        shifts: (F,) [s] constant time from each frame's state to its exposure (another camera of a
            rig, whose frames join the first camera's states), added to ``delta``; needs ``delta``.
    """

    poses: Sequence[int]
    velocities: Sequence[int] | None = None
    omegas: np.ndarray | None = None
    extrinsic: int | None = None
    delta: int | None = None
    camera: int | None = None
    shifts: np.ndarray | None = None


def _se3_exp(xi: np.ndarray) -> np.ndarray:
    """Transforms (F, 4, 4) of twists ``[w; v]`` (F, 6) (GTSAM's ``Pose3.Expmap``)."""
    w, v = xi[:, :3], xi[:, 3:]
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-8
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    c = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    W = skew_batch(w)
    W2 = W @ W
    T = np.tile(np.eye(4), (len(xi), 1, 1))
    T[:, :3, :3] += a[:, None, None] * W + b[:, None, None] * W2
    V = np.eye(3) + b[:, None, None] * W + c[:, None, None] * W2
    T[:, :3, 3] = np.einsum("nij,nj->ni", V, v)
    return T


def skew_batch(w: np.ndarray) -> np.ndarray:
    """Skew matrices (N, 3, 3) of vectors (N, 3)."""
    W = np.zeros((len(w), 3, 3))
    W[:, 0, 1], W[:, 0, 2], W[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    W[:, 1, 0], W[:, 2, 0], W[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return W


def adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint maps (..., 6, 6) of transforms (..., 4, 4) for twists ``[w; v]``: ``T Exp(x) T^-1 = Exp(Ad x)``."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    A = np.zeros((*T.shape[:-2], 6, 6))
    A[..., :3, :3] = R
    A[..., 3:, 3:] = R
    A[..., 3:, :3] = skew_batch(t.reshape(-1, 3)).reshape(*t.shape[:-1], 3, 3) @ R
    return A


def _inverse(T: np.ndarray) -> np.ndarray:
    R, t = T[..., :3, :3], T[..., :3, 3]
    out = np.zeros_like(T)
    out[..., :3, :3] = np.swapaxes(R, -1, -2)
    out[..., :3, 3] = -np.einsum("...ji,...j->...i", R, t)
    out[..., 3, 3] = 1.0
    return out


@dataclass
class _Inputs:
    """The variable values one pass used."""

    poses: np.ndarray  # (F, 4, 4)
    velocities: np.ndarray | None  # (F, 3)
    extrinsic: np.ndarray  # (4, 4) T_imu_cam
    delta: float
    camera: np.ndarray  # (4 + D,) CameraModel.parameters


@dataclass
class _Pass:
    """One pass over every corner: whitened residuals and (optionally) their Jacobians."""

    inputs: _Inputs
    residuals: np.ndarray  # (N, 2) whitened (after the Huber kernel)
    d_camera_pose: np.ndarray | None = None  # (N, 2, 6) w.r.t. a right perturbation of C_n
    d_parameters: np.ndarray | None = None  # (N, 2, 4 + D)
    to_pose: np.ndarray | None = None  # (F, 6, 6) d zeta_C / d xi_X
    to_velocity: np.ndarray | None = None  # (F, 6, 3)
    to_delta: np.ndarray | None = None  # (F, 6, 1)
    to_extrinsic: np.ndarray | None = None  # (6, 6)


class CornerFactors:
    """The corner factors of one graph: ``factors()`` to add, ``residuals(values)`` for reports.

    Args:
        observations: the frames' corners, one frame per entry of ``keys.poses``.
        camera: the camera (its model; its parameters when ``keys.camera`` is None).
        keys: the variables (``CornerKeys``).
        sigma_px: [px] corner noise (per image axis) the residuals are whitened with.
        huber_k: Huber kernel width [sigmas] per corner (None: least squares).
    """

    def __init__(
        self,
        observations: Sequence[FrameObservation],
        camera: CameraModel,
        keys: CornerKeys,
        sigma_px: float,
        huber_k: float | None = None,
    ) -> None:
        if len(observations) != len(keys.poses):
            raise ValueError("one pose key per observed frame")
        if (keys.delta is None) != (keys.velocities is None) or (keys.delta is None) != (keys.omegas is None):
            raise ValueError("the time-offset correction needs the velocities and the gyro rates, and only it")
        if keys.shifts is not None and (keys.delta is None or len(keys.shifts) != len(keys.poses)):
            raise ValueError("per-frame time shifts need the time-offset correction and one shift per frame")
        self.camera, self.keys = camera, keys
        self.sigma_px, self.huber_k = float(sigma_px), huber_k
        self.points = np.concatenate([o.points for o in observations])
        self.measured = np.concatenate([o.uv for o in observations])
        sizes = [len(o.ids) for o in observations]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.frame_of = np.repeat(np.arange(len(observations)), sizes)
        self._last: _Pass | None = None
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ graph
    def factors(self) -> list[gtsam.CustomFactor]:
        """One ``CustomFactor`` per frame, keys ``[X_n, (v_n), (E), (delta), (K)]``."""
        out = []
        for n in range(len(self.keys.poses)):
            corners = int(self.offsets[n + 1] - self.offsets[n])
            noise = gtsam.noiseModel.Unit.Create(2 * corners)
            keys = [self.keys.poses[n]]
            if self.keys.velocities is not None:
                keys.append(self.keys.velocities[n])
            keys += [k for k in (self.keys.extrinsic, self.keys.delta, self.keys.camera) if k is not None]
            out.append(gtsam.CustomFactor(noise, keys, self._callback(n)))
        return out

    def _callback(self, n: int):
        def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> np.ndarray:
            return self._frame(n, values, jacobians)

        return error

    # ------------------------------------------------------------------ reading values
    def _shared(self, values: gtsam.Values) -> tuple[np.ndarray, float, np.ndarray]:
        k = self.keys
        extrinsic = values.atPose3(k.extrinsic).matrix() if k.extrinsic is not None else np.eye(4)
        delta = float(values.atVector(k.delta)[0]) if k.delta is not None else 0.0
        camera = values.atVector(k.camera) if k.camera is not None else self.camera.parameters
        return extrinsic, delta, camera

    def _read(self, values: gtsam.Values) -> _Inputs:
        k = self.keys
        poses = np.array([values.atPose3(key).matrix() for key in k.poses])
        velocities = None if k.velocities is None else np.array([values.atVector(key) for key in k.velocities])
        return _Inputs(poses, velocities, *self._shared(values))

    def _current(self, n: int, values: gtsam.Values, need_jacobians: bool) -> _Pass:
        """The last pass if it used exactly frame ``n``'s present variables (and has what is needed), else a new one."""
        last = self._last
        if last is not None and (last.d_camera_pose is not None or not need_jacobians):
            i = last.inputs
            extrinsic, delta, camera = self._shared(values)
            # Byte-wise equality: the cached numbers are exactly what this frame's variables give.
            same = (
                values.atPose3(self.keys.poses[n]).matrix().tobytes() == i.poses[n].tobytes()
                and delta == i.delta
                and camera.tobytes() == i.camera.tobytes()
                and extrinsic.tobytes() == i.extrinsic.tobytes()
                and (
                    i.velocities is None
                    or values.atVector(self.keys.velocities[n]).tobytes() == i.velocities[n].tobytes()
                )
            )
            if same:
                return last
        self._last = self._evaluate(self._read(values), need_jacobians)
        return self._last

    # ------------------------------------------------------------------ the pass
    def _exposure_shift(self, inputs: _Inputs) -> np.ndarray:
        """(F, 4, 4) ``Exp([omega_n; R_n^T v_n] delta)`` (the identity without a time-offset correction)."""
        F = len(inputs.poses)
        if self.keys.delta is None:
            return np.tile(np.eye(4), (F, 1, 1))
        twist = self._twists(inputs)
        return _se3_exp(twist * self._times(inputs)[:, None])

    def _times(self, inputs: _Inputs) -> np.ndarray:
        """(F,) [s] time from each frame's state to its exposure: the correction plus the frame's shift."""
        shifts = np.zeros(len(inputs.poses)) if self.keys.shifts is None else self.keys.shifts
        return shifts + inputs.delta

    def _twists(self, inputs: _Inputs) -> np.ndarray:
        body_velocity = np.einsum("nji,nj->ni", inputs.poses[:, :3, :3], inputs.velocities)
        return np.concatenate([self.keys.omegas, body_velocity], axis=1)

    def _camera_points(self, inputs: _Inputs) -> tuple[np.ndarray, np.ndarray]:
        """The exposure shifts (F, 4, 4) and every corner's target point in its frame's camera (N, 3)."""
        shift = self._exposure_shift(inputs)
        C = (inputs.poses @ shift @ inputs.extrinsic)[self.frame_of]  # T_target_cam per corner
        return shift, np.einsum("nji,nj->ni", C[:, :3, :3], self.points - C[:, :3, 3])  # R^T (p - t)

    def _evaluate(self, inputs: _Inputs, need_jacobians: bool) -> _Pass:
        shift, q = self._camera_points(inputs)
        try:
            camera = self.camera.with_parameters(inputs.camera)
        except CameraModelError:
            if need_jacobians:
                raise
            return _Pass(inputs, np.full_like(self.measured, np.nan))
        if not need_jacobians:
            return _Pass(inputs, self._huber((camera.project(q)[0] - self.measured) / self.sigma_px)[0])
        uv, d_point, d_parameters = camera.project_jacobians(q)
        residuals, kernel = self._huber((uv - self.measured) / self.sigma_px)
        # Right perturbation C Exp([w; u]): q -> q + q x w - u, so d q / d[w; u] = [skew(q), -I].
        d_pose = np.empty((len(q), 2, 6))
        for row in range(2):
            d_pose[:, row, :3] = np.cross(d_point[:, row], q)
            d_pose[:, row, 3:] = -d_point[:, row]
        d_pose /= self.sigma_px
        d_parameters = d_parameters / self.sigma_px
        if kernel is not None:
            d_pose = np.einsum("nij,njk->nik", kernel, d_pose)
            d_parameters = np.einsum("nij,njk->nik", kernel, d_parameters)
        result = _Pass(inputs, residuals, d_pose, d_parameters)
        self._chain(result, shift)
        return result

    def _chain(self, result: _Pass, shift: np.ndarray) -> None:
        """Maps from the variables' perturbations to the camera pose's (``C_n = X_n S_n E``)."""
        inputs = result.inputs
        to_camera = adjoint(_inverse(inputs.extrinsic))  # a perturbation right of S_n moves C by Ad(E^-1) of it
        result.to_extrinsic = np.eye(6)
        result.to_pose = to_camera @ adjoint(_inverse(shift))  # X Exp(x) S = X S Exp(Ad(S^-1) x)
        if self.keys.delta is None:
            return
        twist = self._twists(inputs)
        R_T = np.swapaxes(inputs.poses[:, :3, :3], 1, 2)
        body_velocity = twist[:, 3:]
        # The twist's velocity part R^T v changes with the state's rotation (R Exp(w): R^T v + (R^T v) x w)
        # and with v; either change shifts the exposure pose by delta times it.
        twist_from_pose = np.zeros((len(twist), 6, 6))
        twist_from_pose[:, 3:, :3] = skew_batch(body_velocity)
        dt = self._times(inputs)[:, None, None]
        result.to_pose = result.to_pose + dt * (to_camera @ twist_from_pose)
        twist_from_velocity = np.zeros((len(twist), 6, 3))
        twist_from_velocity[:, 3:, :] = R_T
        result.to_velocity = dt * (to_camera @ twist_from_velocity)
        result.to_delta = to_camera @ twist[:, :, None]

    def _huber(self, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Per-corner Huber: residuals ``s(a) r`` with ``0.5 |s r|^2 = rho(a)``, ``a = |r|``, and ``d(s r)/d r``.

        Returns the (N, 2) residuals and the (N, 2, 2) kernel; the residuals unchanged and no kernel without
        ``huber_k`` or when every corner is inside it.
        """
        k = self.huber_k
        if k is None:
            return raw, None
        a = np.linalg.norm(raw, axis=1)
        outside = a > k
        if not outside.any():
            return raw, None
        a_safe = np.where(outside, a, 1.0)
        s = np.where(outside, np.sqrt(np.maximum(2.0 * k / a_safe - (k / a_safe) ** 2, 0.0)), 1.0)
        ds = np.where(outside, (k**2 / a_safe**3 - k / a_safe**2) / s, 0.0)  # d s / d a
        unit = raw / a_safe[:, None]
        kernel = s[:, None, None] * np.eye(2) + (ds * a_safe)[:, None, None] * np.einsum("ni,nj->nij", unit, unit)
        return raw * s[:, None], kernel

    # ------------------------------------------------------------------ one frame
    def _frame(self, n: int, values: gtsam.Values, jacobians: list | None) -> np.ndarray:
        with self._lock:
            p = self._current(n, values, jacobians is not None)
        rows = slice(self.offsets[n], self.offsets[n + 1])
        if jacobians is not None:
            d_pose = p.d_camera_pose[rows].reshape(-1, 6)
            blocks = [d_pose @ p.to_pose[n]]
            if self.keys.velocities is not None:
                blocks.append(d_pose @ p.to_velocity[n])
            if self.keys.extrinsic is not None:
                blocks.append(d_pose @ p.to_extrinsic)
            if self.keys.delta is not None:
                blocks.append(d_pose @ p.to_delta[n])
            if self.keys.camera is not None:
                blocks.append(p.d_parameters[rows].reshape(-1, p.d_parameters.shape[2]))
            for slot, block in enumerate(blocks):
                jacobians[slot] = block
        return p.residuals[rows].reshape(-1)

    # ------------------------------------------------------------------ reports
    def residuals(self, values: gtsam.Values) -> np.ndarray:
        """Measured minus predicted corner pixels (N, 2) [px] at ``values`` (no kernel), frames in order."""
        inputs = self._read(values)
        _, q = self._camera_points(inputs)
        return self.measured - self.camera.with_parameters(inputs.camera).project(q)[0]

    def chi2(self, values: gtsam.Values) -> float:
        """Twice the factors' error at ``values``: the sum of squared whitened residuals (after the kernel)."""
        return float(np.sum(self._evaluate(self._read(values), need_jacobians=False).residuals ** 2))


__all__ = ["CornerFactors", "CornerKeys", "adjoint", "skew", "skew_batch"]
