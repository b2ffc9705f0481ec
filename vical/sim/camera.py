"""Camera observation backends: what the simulated camera reports for one exposure.

Both backends take the camera's optical-frame pose ``T_world_cam`` (OpenCV axes, see
``docs/conventions.md``) at the exposure instant and return the target corners it sees:

- ``ProjectBackend``: analytic projection of the target's points through the camera model,
  visibility rules that mirror what the detector needs (``VisibilityRules``: the whole
  checkerboard, or the aprilgrid tags seen whole in a partial view), and Gaussian pixel noise.
  Fast; used for training.
- ``RenderBackend``: MuJoCo renders a wider undistorted pinhole image at that pose (offscreen,
  EGL), the image is warped through the lens distortion (``cv2.remap`` with maps from
  undistorting every output pixel) and an injected detector finds the corners, as a real one
  would (the whole checkerboard or nothing; the aprilgrid tags it decodes). A lens that sees
  further than ``MAX_PINHOLE_RAY_ANGLE`` from its axis (a fisheye, up to 180 deg and beyond) is
  rendered as the faces of a cube map instead (pinhole views 90 deg wide along the camera's
  axes), and the warp samples each ray from the face it crosses; pixels without a ray (outside
  a fisheye's image circle) are black.

The exposure pose is interpolated between the physics steps around the exposure instant
(``interpolate_pose``), so time offsets below one physics step are represented.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from vical.config_checks import require_range
from vical.data import Target
from vical.geometry import CameraModel, interpolate_transform
from vical.geometry.rolling_shutter import exposed_rows
from vical.signals import interrupts_held

Detector = Callable[[np.ndarray, Target], tuple[np.ndarray, np.ndarray]]
"""``detector(image (H, W) uint8, target) -> (corners (K, 2) float64 [px], ids (K,) int64)``."""

_NO_CORNERS = (np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
# Beyond this angle from the axis one pinhole render would spend most of its pixels on the image border.
MAX_PINHOLE_RAY_ANGLE = np.deg2rad(60.0)
# Cube faces as rotations R_cam_face (each face's +z along one camera axis); the front face first.
_CUBE_FACES = (
    np.eye(3),
    np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),  # looks along +x
    np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),  # -x
    np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),  # +y
    np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),  # -y
    np.diag([-1.0, 1.0, -1.0]),  # -z
)


def interpolate_pose(t_ns: int, t0_ns: int, T0: np.ndarray, t1_ns: int, T1: np.ndarray) -> np.ndarray:
    """Pose (4, 4) at ``t0_ns <= t_ns <= t1_ns`` between the poses ``T0`` at ``t0_ns`` and ``T1`` at ``t1_ns``.

    Linear in translation, geodesic in rotation; integer-ns arithmetic keeps sub-step offsets exact.
    """
    if not t0_ns <= t_ns <= t1_ns:
        raise ValueError(f"t = {t_ns} ns lies outside the interval [{t0_ns}, {t1_ns}] ns")
    if t1_ns == t0_ns:
        return np.array(T0, dtype=float)
    return interpolate_transform(T0, T1, (t_ns - t0_ns) / (t1_ns - t0_ns))


@dataclass(frozen=True)
class VisibilityRules:
    """When the analytic backend reports a view, mirroring what the target's detector needs.

    Defaults were measured with the ``render`` backend and ``detect_checkerboard`` over 300
    random views (``docs/sensors.md``): detection succeeded in 25 % of views whose grid fits with
    less than a quarter square of margin and in every view with half a square or more; it held
    up to about 60 deg of obliquity and failed beyond 65 deg.

    Attributes:
        margin_squares: the grid enlarged by this many squares on every side (the printed squares
            around the outer corners that the detector needs) must lie inside the image.
        border_px: extra distance [px] that enlarged grid keeps from the image edge.
        max_obliquity: largest angle [rad] between the board normal and the line of sight to
            the board centre (grazing views fail detection).
        min_corner_spacing_px: smallest image distance [px] between neighbouring corners (smaller
            squares blur together).
        tag_border_px: aprilgrid: a tag is seen when its square keeps this distance [px] from the
            image edge (``detect_aprilgrid``'s ``min_border_px``); partial views report the tags
            that pass, with their four corners each.
        min_tag_px: aprilgrid: shortest tag side [px] in the image. In renders of a 6 x 6 grid of
            88 mm tags aruco decoded 70-87 % of the tags 24-40 px wide and every larger one.

    For an aprilgrid, ``max_obliquity`` applies per tag (line of sight to the tag's centre) and
    ``margin_squares``, ``border_px`` and ``min_corner_spacing_px`` do not apply.
    """

    margin_squares: float = 0.5
    border_px: float = 0.0
    max_obliquity: float = 1.05
    min_corner_spacing_px: float = 8.0
    tag_border_px: float = 4.0
    min_tag_px: float = 32.0

    def __post_init__(self) -> None:
        require_range("visibility.margin_squares", self.margin_squares, 0.0, 5.0)
        require_range("visibility.tag_border_px", self.tag_border_px, 0.0)
        require_range("visibility.min_tag_px", self.min_tag_px, 0.0)
        require_range("visibility.border_px", self.border_px, 0.0)
        require_range("visibility.max_obliquity", self.max_obliquity, 0.0, np.pi / 2, high_open=True)
        require_range("visibility.min_corner_spacing_px", self.min_corner_spacing_px, 0.0)


def grid_outline(target: Target, margin_squares: float, per_edge: int = 16) -> np.ndarray:
    """(4 * per_edge, 3) [m] board-frame points along the grid's outline enlarged by ``margin_squares``.

    Points along the edges, not only the four corners: lens distortion bends straight edges.
    """
    dx, dy = margin_squares * target.row_spacing, margin_squares * target.col_spacing
    x1, y1 = (target.rows - 1) * target.row_spacing + dx, (target.cols - 1) * target.col_spacing + dy
    corners = np.array([[-dx, -dy, 0.0], [-dx, y1, 0.0], [x1, y1, 0.0], [x1, -dy, 0.0]])
    s = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
    return np.vstack([corners[i] + s * (corners[(i + 1) % 4] - corners[i]) for i in range(4)])


def tag_outlines(target: Target, per_edge: int = 4) -> np.ndarray:
    """(T, 4 * per_edge, 3) [m] board points along each aprilgrid tag's square (edges bend under distortion)."""
    corners = target.points[target.tag_corner_ids(np.arange(target.num_tags))]  # (T, 4, 3) counter-clockwise
    s = np.linspace(0.0, 1.0, per_edge, endpoint=False)[None, :, None]
    edges = [corners[:, i, None] + s * (corners[:, (i + 1) % 4, None] - corners[:, i, None]) for i in range(4)]
    return np.concatenate(edges, axis=1)


class ProjectBackend:
    """Analytic observations: projected target corners with visibility rules and pixel noise.

    Args:
        target: the calibration target.
        T_world_board: (4, 4) target pose in the world.
        pixel_noise_px: sigma [px] of the Gaussian noise on each corner coordinate.
        rules: visibility rules.
    """

    def __init__(
        self,
        target: Target,
        T_world_board: np.ndarray,
        pixel_noise_px: float = 0.25,
        rules: VisibilityRules | None = None,
    ) -> None:
        require_range("sensor.pixel_noise_px", pixel_noise_px, 0.0)
        self.target = target
        self.T_world_board = np.asarray(T_world_board, dtype=float)
        self.pixel_noise_px = float(pixel_noise_px)
        self.rules = rules or VisibilityRules()
        self._ids = np.arange(target.num_points, dtype=np.int64)
        self._cos_max_obliquity = float(np.cos(self.rules.max_obliquity))
        if target.kind == "checkerboard":
            self._points_and_outline = np.vstack([target.points, grid_outline(target, self.rules.margin_squares)])
        else:
            self._tag_ids = target.tag_corner_ids(np.arange(target.num_tags))  # (T, 4)
            self._tag_outlines = tag_outlines(target)  # (T, P, 3)

    def _cam_board(self, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R_world_cam, t_world_cam = T_world_cam[:3, :3], T_world_cam[:3, 3]
        R_cam_board = R_world_cam.T @ self.T_world_board[:3, :3]
        t_cam_board = (self.T_world_board[:3, 3] - t_world_cam) @ R_world_cam
        return R_cam_board, t_cam_board

    def ideal_observation(self, camera: CameraModel, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free corners (K, 2) [px] and their ids (K,) the rules say are seen (empty when none).

        A checkerboard is seen whole or not at all (``ideal_corners``); an aprilgrid reports the
        four corners of every tag that passes the rules (``ideal_tags``).
        """
        if self.target.kind == "aprilgrid":
            return self.ideal_tags(camera, T_world_cam)
        uv = self.ideal_corners(camera, T_world_cam)
        return _NO_CORNERS if uv is None else (uv, self._ids.copy())

    def ideal_tags(self, camera: CameraModel, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Aprilgrid corners (K, 2) [px] and ids (K,), sorted by id, of the tags the rules say are seen.

        A tag is seen when its centre is in front of the camera within ``max_obliquity`` of the
        board normal, its square projects ``tag_border_px`` inside the image, and its shortest
        side is at least ``min_tag_px``.
        """
        R, t = self._cam_board(T_world_cam)
        outline = self._tag_outlines
        centres = outline.mean(axis=1) @ R.T + t  # (T, 3)
        distance = np.linalg.norm(centres, axis=1)
        seen = (centres[:, 2] > 0) & (-(centres @ R[:, 2]) >= self._cos_max_obliquity * distance)
        uv_out, front = camera.project(outline.reshape(-1, 3) @ R.T + t)
        inside = front & camera.in_image(uv_out, self.rules.tag_border_px)
        seen &= inside.reshape(outline.shape[:2]).all(axis=1)
        uv_pts, front_pts = camera.project(self.target.points @ R.T + t)
        quads = uv_pts[self._tag_ids]  # (T, 4, 2)
        side = np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=2).min(axis=1)
        seen &= front_pts[self._tag_ids].all(axis=1) & (side >= self.rules.min_tag_px)
        ids = np.sort(self._tag_ids[seen].ravel())
        return uv_pts[ids], ids

    def ideal_corners(self, camera: CameraModel, T_world_cam: np.ndarray) -> np.ndarray | None:
        """Noise-free checkerboard corner pixels (N, 2) in id order, or None when the board is not seen."""
        if self.target.kind != "checkerboard":
            raise ValueError(f"ideal_corners is for checkerboards; use ideal_observation for a {self.target.kind}")
        R_cam_board, t_cam_board = self._cam_board(T_world_cam)
        if not self._faces_camera(R_cam_board, t_cam_board):
            return None
        # One projection of the grid points followed by the enlarged outline.
        uv, in_front = camera.project(self._points_and_outline @ R_cam_board.T + t_cam_board)
        n = self.target.num_points
        if not np.all(in_front) or not np.all(camera.in_image(uv[n:], self.rules.border_px)):
            return None
        if self._min_spacing(uv[:n]) < self.rules.min_corner_spacing_px:
            return None
        return uv[:n]

    def observe(
        self, camera: CameraModel, T_world_cam: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Corners (K, 2) [px] with pixel noise and their ids (K,); empty when the board is not seen."""
        uv, ids = self.ideal_observation(camera, T_world_cam)
        if not len(ids):
            return _NO_CORNERS
        return uv + self.pixel_noise_px * rng.standard_normal(uv.shape), ids

    def observe_rolling(
        self,
        camera: CameraModel,
        pose_at: Callable[[np.ndarray], np.ndarray],
        line_delay: float,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A rolling shutter's ``observe``: each corner seen from the pose at its own row's time.

        ``pose_at(dt)`` gives ``T_world_cam`` (K, 4, 4) at ``dt`` (K,) [s] after the timestamp (row 0's exposure);
        which corners are seen is decided at the middle row's pose (``vical.geometry.rolling_shutter``).
        """
        middle = pose_at(np.array([0.5 * line_delay * camera.height]))[0]
        uv, ids = self.ideal_observation(camera, middle)
        if not len(ids):
            return _NO_CORNERS
        points = self.target.points[ids] @ self.T_world_board[:3, :3].T + self.T_world_board[:3, 3]
        uv = exposed_rows(camera, points, pose_at, line_delay, uv)
        return uv + self.pixel_noise_px * rng.standard_normal(uv.shape), ids

    def _faces_camera(self, R_cam_board: np.ndarray, t_cam_board: np.ndarray) -> bool:
        center = R_cam_board @ self.target.center + t_cam_board
        distance = float(np.sqrt(center @ center))
        if center[2] <= 0 or distance == 0:
            return False
        # The printed side faces the camera when its normal points back along the line of sight.
        cos_view = -float(R_cam_board[:, 2] @ center) / distance
        return cos_view >= self._cos_max_obliquity

    def _min_spacing(self, uv: np.ndarray) -> float:
        grid = uv.reshape(self.target.rows, self.target.cols, 2)
        along_rows = np.diff(grid, axis=0)
        along_cols = np.diff(grid, axis=1)
        shortest_sq = min((along_rows * along_rows).sum(axis=2).min(), (along_cols * along_cols).sum(axis=2).min())
        return float(np.sqrt(shortest_sq))


# ---------------------------------------------------------------------------------- rendering
# A rolling shutter is rendered in bands of rows, each at its middle row's time: a row is then off its own time by at
# most half a band's readout, and off its place by the image's motion over that time. Bands are thin enough for that
# to stay within BAND_ERROR_PX, half the detector's noise on rendered boards (0.07-0.12 px RMS, docs/sensors.md).
BAND_ERROR_PX = 0.05


def rolling_bands(shift_px: float, height: int) -> int:
    """Bands of rows a rolling shutter's render needs when the image moves ``shift_px`` [px] during the readout."""
    return int(np.clip(np.ceil(abs(shift_px) / (2.0 * BAND_ERROR_PX)), 1, height))


def readout_shift(camera: CameraModel, points_world: np.ndarray, pose_at: Callable, line_delay: float) -> float:
    """[px] the farthest any of ``points_world`` (K, 3) in front of the camera moves in the image during the readout
    (between row 0's and the last row's poses); 0 when none is in front at both."""
    T = pose_at(np.array([0.0, line_delay * camera.height]))
    uv = []
    for T_world_cam in T:
        p = (points_world - T_world_cam[:3, 3]) @ T_world_cam[:3, :3]
        uv.append(camera.project(p))
    (first, front_first), (last, front_last) = uv
    both = front_first & front_last
    return float(np.max(np.linalg.norm(last[both] - first[both], axis=1))) if both.any() else 0.0


def render_pinhole(camera: CameraModel, width: int, height: int, margin_px: float = 2.0) -> CameraModel:
    """The undistorted pinhole camera (W x H render) whose image covers every ray of ``camera``'s image.

    Square pixels and a centred principal point (as MuJoCo renders); the focal length is the
    largest that keeps the undistorted rays of all output pixels ``margin_px`` inside the render,
    so the warp never samples outside it.
    """
    u = np.arange(camera.width, dtype=float)
    v = np.arange(camera.height, dtype=float)
    # The image border maps to the extreme rays for every invertible lens.
    border = np.vstack(
        [
            np.stack([u, np.zeros_like(u) - 0.5], 1),
            np.stack([u, np.full_like(u, camera.height - 0.5)], 1),
            np.stack([np.zeros_like(v) - 0.5, v], 1),
            np.stack([np.full_like(v, camera.width - 0.5), v], 1),
        ]
    )
    xy = camera.undistort(camera.pixels_to_normalized(border))
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    f = min((cx + 0.5 - margin_px) / np.nanmax(np.abs(xy[:, 0])), (cy + 0.5 - margin_px) / np.nanmax(np.abs(xy[:, 1])))
    return CameraModel("radtan", int(width), int(height), float(f), float(f), cx, cy)


def cube_face_pinhole(width: int, height: int, margin_px: float = 2.0) -> CameraModel:
    """The W x H pinhole of one cube face: rays up to 45 deg off its axis land ``margin_px`` inside its image."""
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    return CameraModel("radtan", int(width), int(height), cx - margin_px, cy - margin_px, cx, cy)


@dataclass(frozen=True)
class WarpViews:
    """The pinhole renders a camera's image is warped from, stacked vertically into one atlas image.

    Attributes:
        rotations: (V, 3, 3) ``R_cam_view`` of each render.
        pinhole: the renders' pinhole (all the same size).
        map_x, map_y: (H, W) float32 ``cv2.remap`` maps of the camera's pixels into the atlas.
        seen: (H, W) bool, the pixels the camera's model has a ray for (the others are black).
    """

    rotations: np.ndarray
    pinhole: CameraModel
    map_x: np.ndarray
    map_y: np.ndarray
    seen: np.ndarray


def _pixel_rays(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    return camera.bearings(np.stack([u.ravel(), v.ravel()], axis=1))


def warp_views(camera: CameraModel, width: int, height: int) -> WarpViews:
    """One wide pinhole render (``render_pinhole``) when every ray of ``camera`` lies within
    ``MAX_PINHOLE_RAY_ANGLE`` of its axis, else the cube faces its rays cross (``cube_face_pinhole``)."""
    rays, seen = _pixel_rays(camera)
    shape = (camera.height, camera.width)
    if np.all(rays[seen, 2] > np.cos(MAX_PINHOLE_RAY_ANGLE)):
        pinhole = render_pinhole(camera, width, height)
        map_x, map_y = distortion_maps(camera, pinhole)
        return WarpViews(np.eye(3)[None], pinhole, map_x, map_y, seen.reshape(shape))
    pinhole = cube_face_pinhole(width, height)
    faces = np.array(_CUBE_FACES)
    face = np.argmax(np.einsum("fi,ni->nf", faces[:, :, 2], np.where(seen[:, None], rays, 0.0)), axis=1)
    used = np.unique(face[seen])
    src = np.full((len(rays), 2), -1.0)
    for slot, f in enumerate(used):
        mine = seen & (face == f)
        src[mine] = pinhole.project(rays[mine] @ faces[f])[0] + [0.0, slot * height]
    map_x, map_y = (src[:, i].reshape(shape).astype(np.float32) for i in range(2))
    return WarpViews(faces[used], pinhole, map_x, map_y, seen.reshape(shape))


def distortion_maps(camera: CameraModel, pinhole: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.remap`` maps (H, W) float32: for each pixel of ``camera``, where its ray lands in ``pinhole``'s image
    (-1 for pixels without a ray in front of the camera)."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    xy = camera.undistort(camera.pixels_to_normalized(uv))
    src = np.nan_to_num(pinhole.normalized_to_pixels(xy), nan=-1.0)
    shape = (camera.height, camera.width)
    return src[:, 0].reshape(shape).astype(np.float32), src[:, 1].reshape(shape).astype(np.float32)


def set_gl_camera(gl_camera: mujoco.MjvGLCamera, T_world_cam: np.ndarray, pinhole: CameraModel) -> None:
    """Point one of MuJoCo's scene cameras (``mjvGLCamera``) along an OpenCV pose with a pinhole's frustum.

    MuJoCo's GL camera looks along ``forward`` with ``up`` as image up; the OpenCV frame looks
    along +z with +y down, so ``forward = z_cam`` and ``up = -y_cam``. The frustum at the near plane
    spans the pixel edges: pixel ``u`` (centre at integer ``u``) covers ``[u - 0.5, u + 0.5]``.
    """
    R = T_world_cam[:3, :3]
    gl_camera.pos[:] = T_world_cam[:3, 3]
    gl_camera.forward[:] = R[:, 2]
    gl_camera.up[:] = -R[:, 1]
    near = float(gl_camera.frustum_near)
    left = near * (-0.5 - pinhole.cx) / pinhole.fx
    right = near * (pinhole.width - 0.5 - pinhole.cx) / pinhole.fx
    top = near * (pinhole.cy + 0.5) / pinhole.fy
    bottom = -near * (pinhole.height - 0.5 - pinhole.cy) / pinhole.fy
    gl_camera.frustum_center = 0.5 * (left + right)
    gl_camera.frustum_width = 0.5 * (right - left)
    gl_camera.frustum_top = top
    gl_camera.frustum_bottom = bottom
    gl_camera.orthographic = 0


class RenderBackend:
    """Rendered observations: MuJoCo image -> lens-distortion warp -> detector.

    Build it once per scene (the offscreen renderer costs 0.2-0.4 s); call ``set_camera`` once per
    sensor (computes the warp maps, ~0.4 s at 640 x 480) and ``observe`` per exposure (one render, or
    one per cube face a fisheye needs, see ``warp_views``).

    Args:
        model: the compiled scene (``mujoco.MjModel``) whose offscreen buffer holds ``render_size``.
        target: the target the detector looks for.
        detector: corner detector (e.g. ``vical.calib.detection.checkerboard.detect_checkerboard``).
        render_size: (W, H) [px] of the undistorted render; larger than the camera image so that
            the warp has the rays beyond the pinhole's field of view that barrel distortion pulls in.
        camera_name: the rig's MuJoCo camera (its headlight lights the scene).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        target: Target,
        detector: Detector,
        render_size: tuple[int, int] = (704, 528),
        camera_name: str = "cam",
    ) -> None:
        width, height = (int(s) for s in render_size)
        max_w, max_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
        if width > max_w or height > max_h:
            raise ValueError(
                f"render_size {width} x {height} exceeds the scene's offscreen buffer {max_w} x {max_h}; "
                "raise <visual><global offwidth offheight> in the scene or use a smaller render_size"
            )
        self.target = target
        self.detector = detector
        self._camera_name = model.camera(camera_name).name
        with interrupts_held():
            self._renderer = mujoco.Renderer(model, height=height, width=width)
        self._size = (width, height)
        self.camera: CameraModel | None = None
        self.views: WarpViews | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) [px] of the undistorted render."""
        return self._size

    @property
    def pinhole(self) -> CameraModel | None:
        """The pinhole of the renders (one, or each cube face's)."""
        return None if self.views is None else self.views.pinhole

    def set_camera(self, camera: CameraModel) -> None:
        """Prepare the render pinholes and the warp maps of a (new) sensor's camera."""
        self.camera = camera
        self.views = warp_views(camera, *self._size)

    def image(self, data: mujoco.MjData, T_world_cam: np.ndarray) -> np.ndarray:
        """Grey image (H, W) uint8 of the camera at pose ``T_world_cam``, through the lens distortion.

        ``data`` supplies the scene state (the board, lights); the camera pose is ``T_world_cam``.
        """
        image = self._warp(self._atlas(data, T_world_cam), slice(None))
        image[~self.views.seen] = 0
        return image

    def rolling_image(
        self, data: mujoco.MjData, pose_at: Callable[[np.ndarray], np.ndarray], line_delay: float, shift_px: float
    ) -> np.ndarray:
        """A rolling shutter's ``image``: bands of rows, each rendered at the pose of its middle row's time.

        ``pose_at(dt)`` gives ``T_world_cam`` (K, 4, 4) at ``dt`` (K,) [s] after the timestamp (row 0's exposure);
        ``shift_px``: how far the image moves during the readout (``rolling_bands`` makes the bands thin enough).
        """
        height = self.camera.height
        edges = np.linspace(0, height, rolling_bands(shift_px, height) + 1).round().astype(int)
        image = np.zeros((height, self.camera.width), np.uint8)
        for top, bottom in itertools.pairwise(edges):
            T = pose_at(np.array([line_delay * 0.5 * (top + bottom - 1)]))[0]
            image[top:bottom] = self._warp(self._atlas(data, T), slice(top, bottom))
        image[~self.views.seen] = 0
        return image

    def _atlas(self, data: mujoco.MjData, T_world_cam: np.ndarray) -> np.ndarray:
        """The undistorted render(s) the warp samples: one pinhole, or a fisheye's cube faces stacked."""
        views = self.views
        if views is None:
            raise RuntimeError("RenderBackend.set_camera(camera) must be called before rendering")
        renders = []
        for R_cam_view in views.rotations:
            # The scene camera's update places the headlight along the rig's camera; pose and frustum
            # are then replaced by the exposure's.
            self._renderer.update_scene(data, camera=self._camera_name)
            T_world_view = T_world_cam.copy()
            T_world_view[:3, :3] = T_world_cam[:3, :3] @ R_cam_view
            for gl_camera in self._renderer.scene.camera:
                set_gl_camera(gl_camera, T_world_view, views.pinhole)
            with interrupts_held():  # the GL context's calls (vical.signals)
                rendered = self._renderer.render()
            renders.append(cv2.cvtColor(rendered, cv2.COLOR_RGB2GRAY))
        return renders[0] if len(renders) == 1 else np.vstack(renders)

    def _warp(self, atlas: np.ndarray, rows: slice) -> np.ndarray:
        """The image ``rows`` of the camera, sampled from ``atlas`` through the lens distortion."""
        views = self.views
        return cv2.remap(atlas, views.map_x[rows], views.map_y[rows], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def observe(self, data: mujoco.MjData, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Detected corners (K, 2) [px], ids (K,) and the image (H, W) uint8 at ``T_world_cam``."""
        return self._detect(self.image(data, T_world_cam))

    def observe_rolling(
        self, data: mujoco.MjData, pose_at: Callable[[np.ndarray], np.ndarray], line_delay: float, shift_px: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A rolling shutter's ``observe`` (``rolling_image``)."""
        return self._detect(self.rolling_image(data, pose_at, line_delay, shift_px))

    def _detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        corners, ids = self.detector(image, self.target)
        return np.asarray(corners, dtype=float).reshape(-1, 2), np.asarray(ids, dtype=np.int64).reshape(-1), image

    def close(self) -> None:
        """Free the GL context."""
        with interrupts_held():
            self._renderer.close()
