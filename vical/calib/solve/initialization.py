"""Closed-form starting points: focal length from plane homographies, frame poses from PnP.

Wide-angle models (``ds``, ``eucm``, ``omni``, ``omni-radtan``) start as the stereographic projection they all
contain (``ds`` with ``xi = 0, alpha = 0.5``; ``eucm`` with ``alpha = 0.5, beta = 1``; ``omni`` with ``xi = 1``
and no distortion): near the axis it
images like a pinhole of the same focal length, and towards 90 deg it stays much closer to a
fisheye lens than a pinhole does. Its focal length is the one under which the views' rays fit
plane homographies best (a pinhole's homographies cannot describe a fisheye image). OpenCV's
``calibrateCamera`` gives radtan a second start (``opencv_camera``).
"""

from __future__ import annotations

import cv2
import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.result import FramePoses
from vical.calib.solve.observations import FrameObservation
from vical.geometry import CameraModel, CameraModelError, make_transform
from vical.geometry.wide_angle import WIDE_ANGLE_MODELS

MIN_INIT_CORNERS = 12  # frames with fewer corners gave metre-level PnP errors; skip them for initialisation
MAX_INIT_VIEWS = 20  # homographies used for the closed-form focal length
HOMOGRAPHY_OUTLIER_FACTOR = 5.0  # a view fitting its homography this many times worse than the median is not used
MIN_HOMOGRAPHY_OUTLIER_PX = 3.0  # [px] ... unless its fit is still this good
MAX_PNP_RMS_PX = 20.0  # [px] a PnP pose that reprojects worse than this is not used as a starting point
# Wide-angle starting coefficients: the stereographic projection ``m = 2 tan(theta / 2)`` (omni's ``xi = 1``: half
# of it, ``tan(theta / 2)``, the focal length scan takes up the factor).
STEREOGRAPHIC = {
    "ds": np.array([0.0, 0.5]),
    "eucm": np.array([0.5, 1.0]),
    "omni": np.array([1.0]),
    "omni-radtan": np.array([1.0, 0.0, 0.0, 0.0, 0.0]),
}
# Rays further than this from the axis are left out of PnP and of the wide-angle focal-length fit: on the
# unit-depth plane PnP works in, their few pixels of model error at the start become huge.
MAX_INIT_RAY_ANGLE = np.deg2rad(85.0)
FOCAL_SCAN = np.geomspace(0.1, 2.0, 60)  # wide-angle focal lengths tried, in image widths


def _homography_fit(obs: FrameObservation, centre: np.ndarray) -> tuple[np.ndarray | None, float]:
    """Homography (3, 3) from board (x, y) [m] to pixels relative to ``centre``, scaled to a unit first
    column, and the RMS [px] of the corners about it; ``(None, inf)`` when it is degenerate."""
    H, _ = cv2.findHomography(obs.points[:, :2], obs.uv - centre, method=0)
    if H is None or not np.all(np.isfinite(H)):
        return None, np.inf
    uv = cv2.perspectiveTransform(obs.points[:, None, :2].astype(np.float64), H).reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((uv - (obs.uv - centre)) ** 2, axis=1))))
    return H / np.linalg.norm(H[:, 0]), rms


def focal_from_homographies(homographies: list[np.ndarray]) -> tuple[float, float]:
    """Zhang's closed form with the principal point fixed (the homographies' pixel origin) and zero skew.

    With ``B = diag(1/fx^2, 1/fy^2, 1)`` the homography columns satisfy ``h1' B h2 = 0`` and
    ``h1' B h1 = h2' B h2``, two linear equations in ``(1/fx^2, 1/fy^2)`` per view.

    Returns:
        (fx, fy) [px].
    """
    rows, rhs = [], []
    for H in homographies:
        h1, h2 = H[:, 0], H[:, 1]
        rows += [[h1[0] * h2[0], h1[1] * h2[1]], [h1[0] ** 2 - h2[0] ** 2, h1[1] ** 2 - h2[1] ** 2]]
        rhs += [-h1[2] * h2[2], -(h1[2] ** 2 - h2[2] ** 2)]
    if len(rows) < 4:
        raise CalibrationError(
            f"intrinsic initialisation needs at least 2 views of the target with >= {MIN_INIT_CORNERS} corners"
        )
    ab, *_ = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)
    if np.any(ab <= 0):
        raise CalibrationError(
            "the target views do not determine the focal length (the board is seen almost head-on in every "
            "frame); tilt the board by 20-60 deg relative to the camera in some views"
        )
    return float(1.0 / np.sqrt(ab[0])), float(1.0 / np.sqrt(ab[1]))


def _consistent_homographies(fits: list[tuple[np.ndarray | None, float]]) -> list[np.ndarray]:
    """Homographies of the views that fit theirs about as well as most views do.

    Lens distortion makes every view fit a homography only approximately; a view with scrambled
    ids or far-off corners fits many times worse and would corrupt Zhang's closed form.
    """
    rms = np.array([r for _, r in fits])
    finite = rms[np.isfinite(rms)]
    if not len(finite):
        return []
    limit = max(HOMOGRAPHY_OUTLIER_FACTOR * float(np.median(finite)), MIN_HOMOGRAPHY_OUTLIER_PX)
    return [H for H, r in fits if H is not None and r <= limit]


def starting_camera(model: str, camera: CameraModel) -> CameraModel:
    """A camera of ``model`` with ``camera``'s focal lengths and principal point, and no distortion (pinhole
    models) or the stereographic coefficients (wide-angle models)."""
    coeffs = STEREOGRAPHIC.get(model)
    return CameraModel(model, camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy, coeffs)


def opencv_camera(observations: list[FrameObservation], size: tuple[int, int]) -> CameraModel | None:
    """A radtan start from OpenCV's ``calibrateCamera`` (its own closed form refined with k3 fixed) on a spread-out
    subset of the views; None when it fails or answers no plausible camera (principal point outside the image).

    A second opinion for the solves that the homography start leaves unconverged: with strong distortion (real
    lenses' k1 of -0.3) Zhang's undistorted focal length can start Levenberg-Marquardt in a valley that never
    converges (a focal length 3x the truth, the principal point outside the image).
    """
    usable = [o for o in observations if len(o.ids) >= MIN_INIT_CORNERS]
    usable = usable[:: max(1, len(usable) // (2 * MAX_INIT_VIEWS))]
    if len(usable) < 3:
        return None
    objects = [o.points.astype(np.float32) for o in usable]
    pixels = [o.uv.astype(np.float32) for o in usable]
    try:
        _, K, dist, *_ = cv2.calibrateCamera(objects, pixels, size, None, None, flags=cv2.CALIB_FIX_K3)
    except cv2.error:
        return None
    try:
        camera = CameraModel("radtan", *size, K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.asarray(dist, float).ravel()[:4])
    except CameraModelError:  # not finite, or a focal length that is not positive
        return None
    return camera if camera.principal_point_in_image else None


def initial_camera(observations: list[FrameObservation], model: str, size: tuple[int, int]) -> CameraModel:
    """A starting camera of ``model`` with the image centre as principal point: no distortion and Zhang's focal
    lengths (pinhole models), or the stereographic projection whose focal length best straightens the views."""
    w, h = size
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    usable = [o for o in observations if len(o.ids) >= MIN_INIT_CORNERS] or observations
    usable = usable[:: max(1, len(usable) // MAX_INIT_VIEWS)]  # a spread-out subset is plenty for a start
    if model in WIDE_ANGLE_MODELS:
        return _stereographic_camera(usable, model, w, h)
    fx, fy = focal_from_homographies(_consistent_homographies([_homography_fit(o, centre) for o in usable]))
    return CameraModel(model, w, h, fx, fy, centre[0], centre[1])


def _stereographic_camera(observations: list[FrameObservation], model: str, w: int, h: int) -> CameraModel:
    """The stereographic ``model`` camera whose focal length (scanned over ``FOCAL_SCAN``) makes the views' rays
    fit plane homographies best: the least median over views of their RMS angular misfit times the focal
    length (a pixel scale: angles alone shrink as the focal length grows)."""
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    best, best_misfit = None, np.inf
    for f in FOCAL_SCAN * w:
        camera = CameraModel(model, w, h, f, f, cx, cy, STEREOGRAPHIC[model])
        misfits = [_ray_homography_misfit(camera, o) for o in observations]
        misfit = float(np.median(misfits)) * f
        if misfit < best_misfit:
            best, best_misfit = camera, misfit
    if best is None:
        raise CalibrationError(
            f"wide-angle initialisation found no focal length under which the target views look like planes; "
            f"check the target definition and that views hold >= {MIN_INIT_CORNERS} corners"
        )
    return best


def _ray_homography_misfit(camera: CameraModel, obs: FrameObservation) -> float:
    """RMS angle [rad] between the corners' rays and the rays of the plane homography fitted to them (inf when
    too few rays lie within ``MAX_INIT_RAY_ANGLE`` of the axis)."""
    rays, ok = camera.bearings(obs.uv)
    ok &= rays[:, 2] > np.cos(MAX_INIT_RAY_ANGLE)
    if ok.sum() < MIN_INIT_CORNERS:
        return np.inf
    xy = rays[ok, :2] / rays[ok, 2:]
    H, _ = cv2.findHomography(obs.points[ok, :2], xy, method=0)
    if H is None or not np.all(np.isfinite(H)):
        return np.inf
    predicted = np.hstack([obs.points[ok, :2], np.ones((int(ok.sum()), 1))]) @ H.T
    predicted /= np.linalg.norm(predicted, axis=1, keepdims=True) * np.sign(predicted[:, 2:])
    return float(np.sqrt(np.mean(np.arccos(np.clip(np.sum(predicted * rays[ok], axis=1), -1.0, 1.0)) ** 2)))


def undistorted(camera: CameraModel, uv: np.ndarray) -> np.ndarray:
    """Undistorted normalised coordinates (N, 2) of pixels (N, 2) (one batched Newton solve); NaN for rays
    further than ``MAX_INIT_RAY_ANGLE`` from the axis (wide-angle models)."""
    xy = camera.pixels_to_normalized(uv)
    if camera.is_wide_angle:
        xy = camera.undistort(xy)
        xy[np.sum(xy * xy, axis=1) > np.tan(MAX_INIT_RAY_ANGLE) ** 2] = np.nan
    elif np.any(camera.dist != 0) or np.any(camera.distortion_center_offset != 0):
        xy = camera.undistort(xy)
    return xy


def pnp(
    camera: CameraModel, obs: FrameObservation, xy: np.ndarray | None = None, refine: bool = True
) -> tuple[np.ndarray, float] | None:
    """Pose ``T_cam_target`` (4, 4) of one frame and its approximate reprojection RMS [px], or None on failure.

    Pixels are undistorted with the camera model first (or taken as the given undistorted
    normalised ``xy`` (K, 2)), so every model shares one path; corners without a usable ray (NaN)
    are left out. ``refine`` polishes the planar solution to the least reprojection error (needed
    where the pose itself is used, not where a solve refines it anyway).
    """
    if xy is None:
        xy = undistorted(camera, obs.uv)
    usable = np.all(np.isfinite(xy), axis=1)
    if usable.sum() < min(MIN_INIT_CORNERS, len(usable)) or usable.sum() < 4:
        return None
    obj = np.ascontiguousarray(obs.points[usable], dtype=np.float64)
    xy = xy[usable]
    img = np.ascontiguousarray(xy, dtype=np.float64)
    solved = cv2.solvePnP(obj, img, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE)  # planar target
    if not _finite_solution(*solved):
        # IPPE can answer NaN for an ordinary view (seen with OpenCV 5.0 on a 56-corner aprilgrid view at
        # 0.8 m); the iterative solver, started from the view's homography, solves it.
        solved = cv2.solvePnP(obj, img, np.eye(3), None, flags=cv2.SOLVEPNP_ITERATIVE)
        if not _finite_solution(*solved):
            return None
    _, rvec, tvec = solved
    if refine:
        # IPPE solves from the plane homography, not for the least reprojection error: on a wide grid
        # seen in perspective its residuals reached 2.4 px with 0.25 px corner noise.
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, np.eye(3), None, rvec, tvec)
    R = cv2.Rodrigues(rvec)[0]
    T = make_transform(R, tvec.ravel())
    p_cam = obs.points[usable] @ R.T + tvec.ravel()
    if np.any(p_cam[:, 2] <= 0):
        return None
    # RMS in undistorted normalised coordinates scaled by the focal length: pixels to first order.
    err = (p_cam[:, :2] / p_cam[:, 2:] - xy) * [camera.fx, camera.fy]
    rms = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    return T, rms


def _finite_solution(ok: bool, rvec: np.ndarray, tvec: np.ndarray) -> bool:
    return bool(ok) and bool(np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec)))


def frame_poses(
    camera: CameraModel,
    observations: list[FrameObservation],
    min_corners: int = MIN_INIT_CORNERS,
    refine: bool = True,
    only: list[int] | None = None,
) -> dict[int, tuple[np.ndarray, float]]:
    """PnP poses ``{observation index: (T_cam_target, rms [px])}`` of frames good enough to start from
    (``refine``: see ``pnp``; ``only``: these observation indices, else all)."""
    candidates = range(len(observations)) if only is None else only
    used = [k for k in candidates if len(observations[k].ids) >= min_corners]
    if not used:
        return {}
    xy_all = undistorted(camera, np.concatenate([observations[k].uv for k in used]))
    splits = np.cumsum([len(observations[k].ids) for k in used])[:-1]
    poses = {}
    for k, xy in zip(used, np.split(xy_all, splits), strict=True):
        result = pnp(camera, observations[k], xy, refine)
        if result is not None and result[1] < MAX_PNP_RMS_PX:
            poses[k] = result
    return poses


def starting_poses(
    camera: CameraModel, observations: list[FrameObservation], min_corners: int, known: FramePoses | None = None
) -> dict[int, np.ndarray]:
    """``{observation index: T_cam_target}`` to start a solve from: the ``known`` poses of the frames that have
    one (a joint solve's intrinsic start posed them with this camera), PnP for the others, so each frame is posed
    once; a pose that reprojects worse than ``MAX_PNP_RMS_PX`` is left out either way."""
    given = {} if known is None else {int(t): T for t, T in zip(known.t_ns, known.T_cam_target, strict=True)}
    poses = {}
    for k, obs in enumerate(observations):
        T = given.get(obs.t_ns)
        if T is not None and len(obs.ids) >= min_corners:
            rms = float(np.sqrt(np.mean(np.sum(obs.residuals(camera, T) ** 2, axis=1))))
            if rms < MAX_PNP_RMS_PX:
                poses[k] = T
    missing = [k for k in range(len(observations)) if observations[k].t_ns not in given]
    return poses | {k: T for k, (T, _) in frame_poses(camera, observations, min_corners, only=missing).items()}
