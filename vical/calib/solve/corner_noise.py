"""The corner noise a camera-IMU solve starts from: what the views' PnP residuals leave.

Each view's pose takes 6 of its residuals' degrees of freedom; the rest is noise (``estimated_pixel_sigma``).

A rolling shutter (``ViOptions.rolling_shutter``) sees each image row from its own pose, so a moving view's corners
are bent in a way no single pose explains: at 40 us/row the PnP residuals of a synthetic recording read 0.48 px
for 0.30 px of noise, and the solve reweighted the sensors twice to find that out. There the residuals are first
fitted, to first order, by each view's pose moving through the readout ``R`` (one per camera) as the views' poses
move from one to the next,

    r_i = J_i (a_v + R (v_i / H - 1/2) xi_v) + noise,

``J_i`` the corner's pixel Jacobian w.r.t. its view's pose, ``a_v`` that pose's correction, ``xi_v`` its velocity
(central differences of the neighbouring views' poses), ``v_i`` the corner's predicted row (the measured rows carry
the noise). Measured on synthetic recordings at 0-40 us/row (``tests/test_calib_rolling_shutter.py``): the noise
within 0.1 % of PnP's on a global shutter, and the readout within 1 %. A free velocity per view instead absorbed
11 % of the real recording's residuals (what the published intrinsics leave is not white), more than the graph's one
readout can, and the solve reweighted there instead.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from vical.calib.solve.corner_factors import pose_jacobians
from vical.calib.solve.intrinsics import estimated_pixel_sigma
from vical.calib.solve.observations import FrameObservation
from vical.geometry import CameraModel, so3_log

MIN_PIXEL_SIGMA = 0.01  # [px] floor of the estimated corner noise (noise-free data would weight pixels infinitely)
MAX_VELOCITY_GAP = 0.35  # [s] neighbouring views farther apart than this give no velocity (as the time alignment)


def corner_noise(
    camera: CameraModel, views: Sequence[tuple[FrameObservation, np.ndarray]], rolling_shutter: bool
) -> float:
    """[px] the corner noise (per image axis) the views' residuals show at their poses ``T_cam_target`` (4, 4), in
    time order: with a pose per view, or (``rolling_shutter``) a pose per view moving through one readout."""
    if not rolling_shutter:
        residuals = np.concatenate([o.residuals(camera, T) for o, T in views])
        return max(estimated_pixel_sigma(residuals, 6 * len(views)), MIN_PIXEL_SIGMA)
    squares, dof, _ = _readout_fit(camera, views)
    return max(float(np.sqrt(squares / dof)), MIN_PIXEL_SIGMA) if dof > 0 else MIN_PIXEL_SIGMA


def _readout_fit(camera: CameraModel, views: Sequence[tuple[FrameObservation, np.ndarray]]) -> tuple[float, int, float]:
    """(sum of squared residuals, their degrees of freedom, readout [s]) of the least-squares fit of the views'
    residuals by a pose correction per view and one readout (the poses eliminated view by view)."""
    times = np.array([o.t_ns for o, _ in views], dtype=float) * 1e-9
    counts = np.array([len(o.uv) for o, _ in views])
    view_of = np.repeat(np.arange(len(views)), counts)
    q = np.concatenate([o.points @ T[:3, :3].T + T[:3, 3] for o, T in views])
    predicted, d_point, _ = camera.project_jacobians(q)
    J = -pose_jacobians(d_point, q)  # w.r.t. T_cam_target <- Exp(xi) T_cam_target: q moves by w x q + u
    r = np.concatenate([o.uv for o, _ in views]) - predicted
    velocity = _velocities(times, [T for _, T in views])[view_of]
    bend = (predicted[:, 1] / camera.height - 0.5)[:, None] * np.einsum("nai,ni->na", J, velocity)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    normal = np.add.reduceat(np.einsum("nai,naj->nij", J, J), starts)  # (V, 6, 6)
    b_r = np.add.reduceat(np.einsum("nai,na->ni", J, r), starts)[..., None]
    b_bend = np.add.reduceat(np.einsum("nai,na->ni", J, bend), starts)[..., None]
    x_r, x_bend = np.linalg.solve(normal, b_r), np.linalg.solve(normal, b_bend)
    # Inner products of what the views' poses cannot take: u.v - (J^T u)^T N^-1 (J^T v), summed over the views.
    rr = float(np.sum(r * r) - np.sum(b_r * x_r))
    rc = float(np.sum(bend * r) - np.sum(b_bend * x_r))
    cc = float(np.sum(bend * bend) - np.sum(b_bend * x_bend))
    readout = rc / cc if cc > 0 else 0.0
    return rr - readout * rc, int(r.size - 6 * len(views) - 1), readout


def _velocities(times: np.ndarray, poses: Sequence[np.ndarray]) -> np.ndarray:
    """(V, 6) each view's twist ``[w; u]`` [rad/s, m/s] (``T_cam_target <- Exp(xi dt) T_cam_target``) from its
    neighbours' poses; 0 where they are more than ``MAX_VELOCITY_GAP`` apart."""
    out = np.zeros((len(poses), 6))
    for v in range(len(poses)):
        a, b = max(v - 1, 0), min(v + 1, len(poses) - 1)
        dt = times[b] - times[a]
        if b == a or dt > MAX_VELOCITY_GAP:
            continue
        w = so3_log(poses[b][:3, :3] @ poses[a][:3, :3].T) / dt
        out[v] = np.r_[w, (poses[b][:3, 3] - poses[a][:3, 3]) / dt - np.cross(w, poses[v][:3, 3])]
    return out


__all__ = ["MIN_PIXEL_SIGMA", "corner_noise"]
