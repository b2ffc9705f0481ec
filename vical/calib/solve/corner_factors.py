"""Corner factors: every corner's projection in one vectorised pass, one GTSAM factor per frame.

The target's points are known, so they are constants of the factors, not variables. (Points as
variables pinned by priors connect every frame to every other through them: eliminating them makes
the whole problem one dense clique, which made real-size recordings take tens of seconds and GBs.)

Frame ``n`` sees the target from the camera pose (target frame)::

    C_n = X_n * Exp([omega_n; R_n^T v_n] * delta) * E

and with a rolling shutter each corner ``i`` of it from its own row's pose::

    C_i = X_n * Exp([omega_n; R_n^T v_n] * (delta + r * (v_i / H - c))) * E

- ``X_n``: ``Pose3`` key of the frame's state (the IMU pose ``T_target_imu`` at the state time; in the
  intrinsic graph the camera pose ``T_target_cam`` itself, with ``E`` the identity);
- ``v_n``: ``Vector3`` key [m/s] (target frame) and ``omega_n`` [rad/s] the bias-corrected gyro rate
  at the state time (a constant), with ``delta``, a ``Vector1`` key [s], the time-offset correction:
  the pose at the exposure instant to first order in ``delta`` (the neglected ``0.5 a delta^2`` is
  5 um at 1 ms);
- ``r``, a ``Vector1`` key [s] (or a known constant), the camera's readout time: the line delay times the
  image height ``H``; ``v_i`` the corner's measured row (row 0 exposed at the frame's time, Kalibr's
  convention, ``docs/formats.md``); ``c`` the row (as a fraction of ``H``) whose exposure the state's time
  is: the middle (0.5) makes ``delta`` the middle row's correction, nearly uncorrelated with ``r`` and
  half as far from the farthest row. First order in the time from the state like ``delta``: its error is
  measured in ``docs/calibration.md`` ("Rolling shutter");
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
from vical.geometry import CameraModel, CameraModelError, skew, so3_exp_batch


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
            rig, whose frames join the first camera's states; a state anchored away from row 0), added to
            ``delta``.
        readout: ``Vector1`` key [s] of the camera's readout time (the line delay times the image height).

    ``velocities`` and ``omegas`` (the motion at the states) come together, and every exposure time
    (``delta``, ``shifts``, ``readout`` or a known readout) needs them.
    """

    poses: Sequence[int]
    velocities: Sequence[int] | None = None
    omegas: np.ndarray | None = None
    extrinsic: int | None = None
    delta: int | None = None
    camera: int | None = None
    shifts: np.ndarray | None = None
    readout: int | None = None


def _se3_exp(xi: np.ndarray) -> np.ndarray:
    """Transforms (F, 4, 4) of twists ``[w; v]`` (F, 6) (GTSAM's ``Pose3.Expmap``): the rotation
    ``so3_exp_batch(w)`` and ``t = v + b w x v + c w x (w x v)``, written with vectors (one per corner with a rolling
    shutter)."""
    w, v = xi[:, :3], xi[:, 3:]
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-8
    t = np.where(small, 1.0, theta)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    c = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    T = np.zeros((len(xi), 4, 4))
    T[:, :3, :3] = so3_exp_batch(w)
    wv = np.cross(w, v)
    T[:, :3, 3] = v + b[:, None] * wv + c[:, None] * np.cross(w, wv)
    T[:, 3, 3] = 1.0
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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (broadcast), without ``np.cross``'s per-call overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def pose_jacobians(d_point: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N, 2, 6) pixel Jacobians w.r.t. a right perturbation of the camera pose, from those (N, 2, 3) w.r.t. the
    camera-frame point ``q`` (N, 3): ``C Exp([w; u])`` moves ``q`` to ``q + q x w - u``."""
    d_pose = np.empty((len(q), 2, 6))
    for row in range(2):
        d_pose[:, row, :3] = np.cross(d_point[:, row], q)
        d_pose[:, row, 3:] = -d_point[:, row]
    return d_pose


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
    readout: float
    camera: np.ndarray  # (4 + D,) CameraModel.parameters


@dataclass
class _Pass:
    """One pass over every corner: whitened residuals and (optionally) their Jacobians.

    The Jacobians w.r.t. the variables that move the camera pose go through ``d_pose``, w.r.t. a right perturbation of
    each corner's camera pose ``C``: with a global shutter by one map per frame from the variables to ``C`` (applied
    per frame: a 6 x 6 product for all its corners), with a rolling shutter every corner has its own pose, and its
    Jacobians are computed per corner at once.
    """

    inputs: _Inputs
    residuals: np.ndarray  # (N, 2) whitened (after the Huber kernel)
    d_parameters: np.ndarray | None = None  # (N, 2, 4 + D) w.r.t. the camera parameters
    d_pose: np.ndarray | None = None  # (N, 2, 6) w.r.t. a right perturbation of C (and of E: C = X S E)
    frame_maps: dict[str, np.ndarray] | None = None  # global shutter: "state", "velocity", "time": (F, 6, k)
    corner_jacobians: dict[str, np.ndarray] | None = None  # rolling: "state", "velocity", "time", "readout": (N, 2, k)


class CornerFactors:
    """The corner factors of one graph: ``factors()`` to add, ``residuals(values)`` for reports.

    Args:
        observations: the frames' corners, one frame per entry of ``keys.poses``.
        camera: the camera (its model; its parameters when ``keys.camera`` is None).
        keys: the variables (``CornerKeys``).
        sigma_px: [px] corner noise (per image axis) the residuals are whitened with.
        huber_k: Huber kernel width [sigmas] per corner (None: least squares).
        readout: [s] the camera's known readout time (line delay times image height) when ``keys.readout`` is
            None; 0: a global shutter.
        row_centre: ``c``, the row (a fraction of the image height) exposed at the state's time plus ``delta``.
    """

    def __init__(
        self,
        observations: Sequence[FrameObservation],
        camera: CameraModel,
        keys: CornerKeys,
        sigma_px: float,
        huber_k: float | None = None,
        readout: float = 0.0,
        row_centre: float = 0.0,
    ) -> None:
        if len(observations) != len(keys.poses):
            raise ValueError("one pose key per observed frame")
        moving = keys.velocities is not None
        if moving != (keys.omegas is not None):
            raise ValueError("the motion at the states is the velocities and the gyro rates together")
        timed = keys.delta is not None or keys.shifts is not None or keys.readout is not None or readout != 0.0
        if timed and not moving:
            raise ValueError("an exposure time away from the states (offset, shifts, readout) needs their motion")
        if keys.shifts is not None and len(keys.shifts) != len(keys.poses):
            raise ValueError("one time shift per frame")
        self.camera, self.keys = camera, keys
        self.sigma_px, self.huber_k = float(sigma_px), huber_k
        self.readout = float(readout)
        self.points = np.concatenate([o.points for o in observations])
        self.measured = np.concatenate([o.uv for o in observations])
        sizes = [len(o.ids) for o in observations]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.frame_of = np.repeat(np.arange(len(observations)), sizes)
        # Exposures: one per frame (a global shutter) or one per corner, at its row's time (a rolling shutter).
        self.rolling = keys.readout is not None or self.readout != 0.0
        self.exposure_frame = self.frame_of if self.rolling else np.arange(len(observations))  # (G,) per exposure
        self.row_fraction = self.measured[:, 1] / camera.height - row_centre  # (N,) v_i / H - c
        self._last: _Pass | None = None
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ graph
    def factors(self) -> list[gtsam.CustomFactor]:
        """One ``CustomFactor`` per frame, keys ``[X_n, (v_n), (E), (delta), (r), (K)]``."""
        out = []
        shared = (self.keys.extrinsic, self.keys.delta, self.keys.readout, self.keys.camera)
        for n in range(len(self.keys.poses)):
            corners = int(self.offsets[n + 1] - self.offsets[n])
            noise = gtsam.noiseModel.Unit.Create(2 * corners)
            keys = [self.keys.poses[n]]
            if self.keys.velocities is not None:
                keys.append(self.keys.velocities[n])
            keys += [k for k in shared if k is not None]
            out.append(gtsam.CustomFactor(noise, keys, self._callback(n)))
        return out

    def _callback(self, n: int):
        def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None) -> np.ndarray:
            return self._frame(n, values, jacobians)

        return error

    # ------------------------------------------------------------------ reading values
    def _shared(self, values: gtsam.Values) -> tuple[np.ndarray, float, float, np.ndarray]:
        k = self.keys
        extrinsic = values.atPose3(k.extrinsic).matrix() if k.extrinsic is not None else np.eye(4)
        delta = float(values.atVector(k.delta)[0]) if k.delta is not None else 0.0
        readout = float(values.atVector(k.readout)[0]) if k.readout is not None else self.readout
        camera = values.atVector(k.camera) if k.camera is not None else self.camera.parameters
        return extrinsic, delta, readout, camera

    def _read(self, values: gtsam.Values) -> _Inputs:
        k = self.keys
        poses = np.array([values.atPose3(key).matrix() for key in k.poses])
        velocities = None if k.velocities is None else np.array([values.atVector(key) for key in k.velocities])
        return _Inputs(poses, velocities, *self._shared(values))

    def _current(self, n: int, values: gtsam.Values, need_jacobians: bool) -> _Pass:
        """The last pass if it used exactly frame ``n``'s present variables (and has what is needed), else a new one."""
        last = self._last
        if last is not None and (last.d_pose is not None or not need_jacobians):
            i = last.inputs
            extrinsic, delta, readout, camera = self._shared(values)
            # Byte-wise equality: the cached numbers are exactly what this frame's variables give.
            same = (
                values.atPose3(self.keys.poses[n]).matrix().tobytes() == i.poses[n].tobytes()
                and delta == i.delta
                and readout == i.readout
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
        """(G, 4, 4) ``Exp([omega_n; R_n^T v_n] dt)`` per exposure (the identity without motion)."""
        if self.keys.velocities is None:
            return np.tile(np.eye(4), (len(self.exposure_frame), 1, 1))
        twist = self._twists(inputs)[self.exposure_frame]
        return _se3_exp(twist * self._times(inputs)[:, None])

    def _times(self, inputs: _Inputs) -> np.ndarray:
        """(G,) [s] time from each exposure's state to it: the frame's shift, the correction and its row's readout."""
        F = len(inputs.poses)
        shifts = np.zeros(F) if self.keys.shifts is None else self.keys.shifts
        times = (shifts + inputs.delta)[self.exposure_frame]
        return times + inputs.readout * self.row_fraction if self.rolling else times

    def _twists(self, inputs: _Inputs) -> np.ndarray:
        body_velocity = np.einsum("nji,nj->ni", inputs.poses[:, :3, :3], inputs.velocities)
        return np.concatenate([self.keys.omegas, body_velocity], axis=1)

    def _camera_points(self, inputs: _Inputs) -> tuple[np.ndarray, np.ndarray]:
        """The exposure shifts (G, 4, 4) and every corner's target point in its exposure's camera (N, 3).

        ``q = C^-1 p`` for ``C = X S E``: one 4 x 4 product per frame (global shutter); with a rolling shutter the
        transforms applied one at a time to the points (3-vectors), not a 4 x 4 product per corner.
        """
        shift = self._exposure_shift(inputs)
        E = inputs.extrinsic
        if not self.rolling:
            C = (inputs.poses @ shift @ E)[self.frame_of]  # T_target_cam
            return shift, np.einsum("nji,nj->ni", C[:, :3, :3], self.points - C[:, :3, 3])  # R^T (p - t)
        X = inputs.poses[self.frame_of]
        in_state = np.einsum("nji,nj->ni", X[:, :3, :3], self.points - X[:, :3, 3])  # X^-1 p
        in_shifted = np.einsum("nji,nj->ni", shift[:, :3, :3], in_state - shift[:, :3, 3])  # S^-1 X^-1 p
        return shift, (in_shifted - E[:3, 3]) @ E[:3, :3]  # E^-1 S^-1 X^-1 p

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
        d_pose = pose_jacobians(d_point, q) / self.sigma_px
        d_parameters = d_parameters / self.sigma_px
        if kernel is not None:
            d_pose = np.einsum("nij,njk->nik", kernel, d_pose)
            d_parameters = np.einsum("nij,njk->nik", kernel, d_parameters)
        result = _Pass(inputs, residuals, d_parameters, d_pose)
        self._chain(result, shift)
        return result

    def _chain(self, result: _Pass, shift: np.ndarray) -> None:
        """The Jacobians w.r.t. the variables behind each corner's camera pose ``C = X_n S E`` (``S``: its exposure's
        shift, (G, 4, 4)): per frame for a global shutter (``_frame_maps``), per corner for a rolling one."""
        if self.rolling:
            result.corner_jacobians = self._corner_jacobians(result.inputs, shift, result.d_pose)
        else:
            result.frame_maps = self._frame_maps(result.inputs, shift)

    def _frame_maps(self, inputs: _Inputs, shift: np.ndarray) -> dict[str, np.ndarray]:
        """Maps (F, 6, k) from the variables' perturbations to a frame's camera pose (one exposure per frame)."""
        to_camera = adjoint(_inverse(inputs.extrinsic))  # a perturbation right of S moves C by Ad(E^-1) of it
        maps = {"state": to_camera @ adjoint(_inverse(shift))}  # X Exp(x) S = X S Exp(Ad(S^-1) x)
        if self.keys.velocities is None:
            return maps
        twist = self._twists(inputs)
        R_T = np.swapaxes(inputs.poses[:, :3, :3], 1, 2)
        # The twist's velocity part R^T v changes with the state's rotation (R Exp(w): R^T v + (R^T v) x w)
        # and with v; either change shifts the exposure pose by dt times it.
        twist_from_pose = np.zeros((len(twist), 6, 6))
        twist_from_pose[:, 3:, :3] = skew_batch(twist[:, 3:])
        dt = self._times(inputs)[:, None, None]
        maps["state"] = maps["state"] + dt * (to_camera @ twist_from_pose)
        twist_from_velocity = np.zeros((len(twist), 6, 3))
        twist_from_velocity[:, 3:, :] = R_T
        maps["velocity"] = dt * (to_camera @ twist_from_velocity)
        maps["time"] = to_camera @ twist[:, :, None]
        return maps

    def _corner_jacobians(self, inputs: _Inputs, shift: np.ndarray, d_pose: np.ndarray) -> dict[str, np.ndarray]:
        """Each corner's Jacobians (N, 2, k) from ``d_pose`` (one exposure per corner): ``_frame_maps``' products with
        the rows written out (``b skew(u) = b x u``), so that no 6 x 6 map is formed per corner."""
        N = len(d_pose)
        d_shifted = (d_pose.reshape(-1, 6) @ adjoint(_inverse(inputs.extrinsic))).reshape(N, 2, 6)
        # Ad(S^-1) = [[R^T, 0], [skew(u) R^T, R^T]], u = -R^T t.
        R_T = np.swapaxes(shift[:, :3, :3], 1, 2)
        u = -np.einsum("nij,nj->ni", R_T, shift[:, :3, 3])
        rotation, translation = d_shifted[:, :, :3], d_shifted[:, :, 3:]
        twist = self._twists(inputs)[self.frame_of]
        dt = self._times(inputs)[:, None, None]
        d_state = np.empty((N, 2, 6))
        d_state[:, :, :3] = np.matmul(rotation + _cross(translation, u[:, None, :]), R_T)
        d_state[:, :, :3] += dt * _cross(translation, twist[:, None, 3:])
        d_state[:, :, 3:] = np.matmul(translation, R_T)
        state_R_T = np.swapaxes(inputs.poses[:, :3, :3], 1, 2)[self.frame_of]
        d_time = np.matmul(d_shifted, twist[:, :, None])
        return {
            "state": d_state,
            "velocity": dt * np.matmul(translation, state_R_T),
            "time": d_time,
            "readout": d_time * self.row_fraction[:, None, None],
        }

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
            k = self.keys
            moved = self._moved(p, n, rows)
            blocks = [moved("state")]
            blocks += [moved("velocity")] if k.velocities is not None else []
            blocks += [p.d_pose[rows].reshape(-1, 6)] if k.extrinsic is not None else []  # C = X S E: E's is C's
            blocks += [moved("time")] if k.delta is not None else []
            blocks += [moved("readout")] if k.readout is not None else []
            blocks += [p.d_parameters[rows].reshape(-1, p.d_parameters.shape[2])] if k.camera is not None else []
            for slot, block in enumerate(blocks):
                jacobians[slot] = block
        return p.residuals[rows].reshape(-1)

    @staticmethod
    def _moved(p: _Pass, n: int, rows: slice):
        """``name -> (2 K, k)``: frame ``n``'s corner Jacobians w.r.t. the variable ``name`` moves the pose by."""
        if p.corner_jacobians is not None:
            return lambda name: p.corner_jacobians[name][rows].reshape(-1, p.corner_jacobians[name].shape[2])
        flat = p.d_pose[rows].reshape(-1, 6)
        return lambda name: flat @ p.frame_maps[name][n]

    # ------------------------------------------------------------------ reports
    def residuals(self, values: gtsam.Values) -> np.ndarray:
        """Measured minus predicted corner pixels (N, 2) [px] at ``values`` (no kernel), frames in order."""
        inputs = self._read(values)
        _, q = self._camera_points(inputs)
        return self.measured - self.camera.with_parameters(inputs.camera).project(q)[0]

    def image_rates(self, values: gtsam.Values) -> np.ndarray | None:
        """(N, 2) [px/s] how fast each corner moves in the image at ``values`` (its pixel's derivative by its exposure
        time), or None without the motion at the states."""
        if self.keys.velocities is None:
            return None
        inputs = self._read(values)
        shift, q = self._camera_points(inputs)
        d_point = self.camera.with_parameters(inputs.camera).project_jacobians(q)[1]
        unwhitened = _Pass(inputs, self.measured, d_pose=pose_jacobians(d_point, q))
        self._chain(unwhitened, shift)
        if unwhitened.corner_jacobians is not None:
            return unwhitened.corner_jacobians["time"][:, :, 0]
        return np.einsum("nij,nj->ni", unwhitened.d_pose, unwhitened.frame_maps["time"][self.frame_of, :, 0])

    def chi2(self, values: gtsam.Values) -> float:
        """Twice the factors' error at ``values``: the sum of squared whitened residuals (after the kernel)."""
        return float(np.sum(self._evaluate(self._read(values), need_jacobians=False).residuals ** 2))


__all__ = ["CornerFactors", "CornerKeys", "adjoint", "pose_jacobians", "skew", "skew_batch"]
