"""A rolling shutter's exposure: each image row at its own time (row 0 at the timestamp, ``docs/formats.md``).

``exposed_rows`` finds where points land when the row a point lands in decides when it is exposed: fixed-point
iterations from its pixel at the timestamp's pose, each point seen from the pose at ``line_delay * v``. Shared by
the corner-level simulators (``vical.calib.synthetic``, ``vical.sim.camera.ProjectBackend``), whose poses come from
their own motion.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from vical.geometry.camera import CameraModel

TOLERANCE_PX = 1e-6  # the rows' pixels are iterated until none moves by more than this
MAX_ITERATIONS = 20  # 2-3 suffice at 40 us/row and 1 rad/s


class RollingShutterError(ValueError):
    """The rows' exposure times did not settle (a readout far longer than the motion allows)."""


def exposed_rows(
    camera: CameraModel,
    points_world: np.ndarray,
    pose_at: Callable[[np.ndarray], np.ndarray],
    line_delay: float,
    uv: np.ndarray,
) -> np.ndarray:
    """Pixels (K, 2) of ``points_world`` (K, 3), each seen at its own row's time.

    Args:
        camera: the camera model.
        points_world: (K, 3) [m] the points in the world.
        pose_at: ``pose_at(dt)`` -> (K, 4, 4) ``T_world_cam`` at ``dt`` (K,) [s] after the timestamp (row 0's time).
        line_delay: [s/row] the time from one row's exposure to the next.
        uv: (K, 2) [px] a first guess of the pixels (e.g. at the timestamp's or the middle row's pose).
    """
    moved = np.inf
    for _ in range(MAX_ITERATIONS):
        T = pose_at(line_delay * uv[:, 1])
        p = np.einsum("kji,kj->ki", T[:, :3, :3], points_world - T[:, :3, 3])  # R^T (p - t)
        new = camera.project(p)[0]
        moved = float(np.max(np.abs(new - uv))) if len(uv) else 0.0
        uv = new
        if moved < TOLERANCE_PX:
            return uv
    raise RollingShutterError(
        f"a rolling shutter's rows did not settle (last step {moved:.2g} px): the line delay is too long"
    )
