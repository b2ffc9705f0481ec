"""Weakly observed parameters and parameters the data cannot tell apart, with motion hints.

The thresholds are 1-sigma values that a well-excited 20 s recording of the paper's camera
(640 x 480, 1 rad FOV, 7 x 6 board at 0.5-1.2 m) beats comfortably; a parameter above its
threshold is flagged, the weakest first (largest sigma / threshold). Correlations between
parameters of different groups (focal length, principal point, distortion, extrinsic rotation,
translation, time offset, biases) show trade-offs the 1-sigma alone hide: a principal-point shift
absorbed by the camera-IMU rotation, say.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.calib.result import Correlation, WeakParameter
from vical.geometry import CameraModel

_TILT_HINT = "move closer to the target and tilt it more (30-60 deg views) so focal length separates from distance"
_BORDER_HINT = "show the target near the image corners and borders, where the lens distortion is largest"
_AXES = {"x": "x (image right)", "y": "y (image down)", "z": "z (optical axis)"}


def _rotate_others_hint(axis: str, what: str) -> str:
    others = " and ".join(_AXES[a] for a in "xyz" if a != axis)
    return f"rotate more about the camera's {others} axes: {what} along/about {_AXES[axis]} shows only then"


_COEFFICIENT_THRESHOLDS = {  # [-]
    "radtan": {"k1": 0.005, "k2": 0.01, "p1": 0.0005, "p2": 0.0005},
    "equidistant": {"k1": 0.005, "k2": 0.01, "k3": 0.02, "k4": 0.02},
    # A 180 deg lens seen over its whole image (30 views, 0.3 px noise) gave 1-sigma of xi 0.004, alpha
    # 0.001 (ds) and alpha 0.001, beta 0.0035 (eucm); ds's focal length trades off against xi (0.45 % of f).
    "ds": {"xi": 0.01, "alpha": 0.003},
    "eucm": {"alpha": 0.003, "beta": 0.01},
    # omni on the same data: xi 0.002, its focal length trading off against xi (0.18 % of f); omni-radtan's xi,
    # k1 and focal length can hardly be told apart (xi 0.03, f 1.5 %): they are reported weak, as they are.
    "omni": {"xi": 0.01},
    "omni-radtan": {"xi": 0.01, "k1": 0.005, "k2": 0.01, "p1": 0.0005, "p2": 0.0005},
}
_FOCAL_THRESHOLD = {"ds": 0.006, "omni": 0.006}  # of the focal length; 0.002 for the other models


LINE_DELAY_HINT = (
    "pan and tilt fast (1 rad/s and more) with the target spanning most of the image height: a rolling shutter "
    "shows as rows that drift apart while the image moves"
)


def thresholds(camera: CameraModel) -> dict[str, float]:
    """1-sigma above which each parameter counts as weakly observed (in the parameter's unit)."""
    t = {
        "fx": _FOCAL_THRESHOLD.get(camera.distortion, 0.002) * camera.fx,  # [px] 0.2 % of the focal length
        "fy": _FOCAL_THRESHOLD.get(camera.distortion, 0.002) * camera.fy,  # [px]
        "cx": 0.003 * camera.width,  # [px] ~2 px at 640 wide
        "cy": 0.003 * camera.height,  # [px]
        "rot_x": np.deg2rad(0.1),  # [rad]
        "rot_y": np.deg2rad(0.1),  # [rad]
        "rot_z": np.deg2rad(0.1),  # [rad]
        "t_x": 0.002,  # [m]
        "t_y": 0.002,  # [m]
        "t_z": 0.002,  # [m]
        "time_offset": 0.0005,  # [s]
        "line_delay": 0.5e-6,  # [s/row] 0.24 ms of readout at 480 rows
    }
    t.update(_COEFFICIENT_THRESHOLDS[camera.distortion])
    return t


# IMU intrinsics (vical.data.ImuIntrinsics): 1-sigma above which they count as weak; a 20 s recording of the
# synthetic motion (vical.calib.synthetic) reaches 0.02-0.1 % and 0.01-0.07 deg.
IMU_INTRINSIC_THRESHOLDS = {
    **{f"{s}_scale_{a}": 0.002 for s in ("accel", "gyro") for a in "xyz"},  # [-] 0.2 %
    **{f"{s}_misalign_{m}": np.deg2rad(0.1) for s in ("accel", "gyro") for m in ("yx", "zx", "zy")},  # [rad]
    **{f"gyro_rot_{a}": np.deg2rad(0.1) for a in "xyz"},  # [rad]
    **{f"g_sens_{r}{c}": 0.001 for r in "xyz" for c in "xyz"},  # [(rad/s)/(m/s^2)]
}


def _imu_intrinsic_hint(name: str) -> str:
    axis = name[-1] if name[-1] in "xyz" else name[-2]
    if name.startswith("gyro_scale_"):
        return f"rotate faster about the IMU's {axis} axis, both ways: a gyro scale error grows with the rate"
    if name.startswith(("gyro_misalign_", "gyro_rot_")):
        return "rotate fast about every IMU axis in turn: a gyro axis misalignment shows as rate leaking between axes"
    if name.startswith("accel_scale_"):
        return f"hold the sensor with the IMU's {axis} axis up and then down (gravity along it, both signs)"
    if name.startswith("accel_misalign_"):
        return "hold the sensor in several orientations, gravity moving between the IMU's axes"
    return "rotate fast while the sensor points in several directions relative to gravity"


def hint(name: str) -> str:
    """Plain-language advice on the motion that would observe ``name`` better."""
    if name in IMU_INTRINSIC_THRESHOLDS:
        return _imu_intrinsic_hint(name)
    if name in ("fx", "fy"):
        return _TILT_HINT
    if name == "cx":
        return "tilt the target left/right (about the image's vertical axis) and show it near the left and right edges"
    if name == "cy":
        return "tilt the target up/down (about the image's horizontal axis) and show it near the top and bottom edges"
    if name in ("k1", "k2", "k3", "k4", "p1", "p2", "xi", "alpha", "beta"):
        return _BORDER_HINT
    if name.startswith("rot_"):
        return _rotate_others_hint(name[-1], "a rotation error")
    if name.startswith("t_"):
        return _rotate_others_hint(name[-1], "the lever arm")
    if name == "time_offset":
        return "move with faster and changing rotation rates: the time offset shows only in fast motion"
    if name == "line_delay":
        return LINE_DELAY_HINT
    return "record longer and hold the sensor in several orientations relative to gravity"


def weak_parameters(names: list[str], covariance: np.ndarray, camera: CameraModel) -> list[WeakParameter]:
    """Parameters whose 1-sigma exceeds its threshold, weakest first.

    Args:
        names: parameter names (P,), see ``CalibrationResult.parameter_names``.
        covariance: (P, P) marginal covariance.
        camera: the calibrated camera (scales the intrinsic thresholds).
    """
    limits = thresholds(camera) | IMU_INTRINSIC_THRESHOLDS
    sigmas = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    weak = [
        WeakParameter(n, float(s), limits[n], hint(n))
        for n, s in zip(names, sigmas, strict=True)
        if n in limits and s > limits[n]
    ]
    return sorted(weak, key=lambda w: -w.ratio)


GROUPS = {
    "focal length": ("fx", "fy"),
    "principal point": ("cx", "cy"),
    "distortion": ("k1", "k2", "k3", "k4", "p1", "p2"),
    "extrinsic rotation": ("rot_x", "rot_y", "rot_z"),
    "extrinsic translation": ("t_x", "t_y", "t_z"),
    "time offset": ("time_offset",),
    "line delay": ("line_delay",),
    "accelerometer bias": ("ba_x", "ba_y", "ba_z"),
    "gyroscope bias": ("bg_x", "bg_y", "bg_z"),
    "accelerometer intrinsics": tuple(n for n in IMU_INTRINSIC_THRESHOLDS if n.startswith("accel_")),
    "gyroscope intrinsics": tuple(n for n in IMU_INTRINSIC_THRESHOLDS if not n.startswith("accel_")),
}
STRONG_CORRELATION = 0.9  # |rho| above which two parameters are hard to tell apart
_PAIR_HINTS = {
    frozenset(("principal point", "extrinsic rotation")): (
        "show the target near every image edge and rotate about the camera's x and y axes both ways, so a "
        "principal-point shift and a camera-IMU rotation look different"
    ),
    frozenset(("focal length", "extrinsic translation")): (
        "vary the distance to the target and move along the optical axis"
    ),
    frozenset(("focal length", "distortion")): _BORDER_HINT,
    frozenset(("principal point", "distortion")): _BORDER_HINT,
    frozenset(("time offset", "extrinsic translation")): "move with faster and changing rotation rates",
    frozenset(("time offset", "line delay")): LINE_DELAY_HINT,
    frozenset(("time offset", "extrinsic rotation")): "move with faster and changing rotation rates",
    frozenset(("extrinsic translation", "accelerometer bias")): (
        "rotate more about all axes and hold the sensor in several orientations relative to gravity"
    ),
    frozenset(("extrinsic rotation", "gyroscope intrinsics")): (
        "the camera-IMU rotation is the accelerometer's, the gyro's axes follow the camera's turns: hold the sensor "
        "in several orientations relative to gravity and accelerate along every axis to tell the two apart"
    ),
}


def group_of(name: str) -> str | None:
    return next((group for group, names in GROUPS.items() if name in names), None)


def correlation_matrix(covariance: np.ndarray) -> np.ndarray:
    """(P, P) the correlations of ``covariance`` (not finite where a parameter's variance is 0 or not finite)."""
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        return covariance / np.outer(sigma, sigma)


def correlations(names: list[str], covariance: np.ndarray, limit: int = 5) -> list[Correlation]:
    """The ``limit`` strongest correlations between parameters of different groups, strongest first.

    Args:
        names: parameter names (P,); covariance: (P, P) their covariance.
    """
    rho = correlation_matrix(covariance)
    pairs = []
    for i, a in enumerate(names):
        for j in range(i + 1, len(names)):
            ga, gb = group_of(a), group_of(names[j])
            if ga is not None and gb is not None and ga != gb and np.isfinite(rho[i, j]):
                pairs.append((abs(rho[i, j]), a, names[j], ga, gb, float(rho[i, j])))
    pairs.sort(key=lambda p: -p[0])
    return [
        Correlation(a, b, value, _PAIR_HINTS.get(frozenset((ga, gb)), _GENERIC_PAIR_HINT))
        for _, a, b, ga, gb, value in pairs[:limit]
    ]


_GENERIC_PAIR_HINT = "record more varied motion: rotate and translate along every axis, near and far"


def correlation_warnings(found: list[Correlation]) -> list[str]:
    """Plain-language notes on pairs correlated beyond ``STRONG_CORRELATION``."""
    return [
        f"{c.a} and {c.b} are strongly correlated (rho = {c.rho:+.2f}): this data can hardly tell them apart; {c.hint}"
        for c in found
        if abs(c.rho) >= STRONG_CORRELATION
    ]


def principal_point_frame_warning(camera: CameraModel, names: list[str], covariance: np.ndarray) -> str:
    """The joint task's note that its camera-IMU rotation is relative to its own principal point.

    The camera frame's axes are set by the principal point: another calibration's principal point 1 px away turns
    the frame, and with it the rotation, by the angle between the rays of neighbouring pixels at the principal
    point, whatever the data (on the real dev set, the 7.1 px between EuRoC's published one and the joint task's on the
    detections turn it by 0.89 deg). The correlations say how closely this data tie the two (the pair also moves
    together within the solve); the fix is the two-stage workflow.
    """
    centre = np.array([[camera.cx, camera.cy], [camera.cx + 1.0, camera.cy], [camera.cx, camera.cy + 1.0]])
    rays, _ = camera.bearings(centre)
    turn = np.degrees(np.arccos(np.clip(rays[1:] @ rays[0], -1.0, 1.0)))
    at, correlation = {n: i for i, n in enumerate(names)}, correlation_matrix(covariance)
    rho = [correlation[at[a], at[b]] for a, b in (("cx", "rot_y"), ("cy", "rot_x"))]
    return (
        f"the camera-IMU rotation is relative to this calibration's principal point: moving cx by 1 px turns it "
        f"{turn[0]:.3f} deg about y, cy by 1 px {turn[1]:.3f} deg about x (in this data rho = {rho[0]:+.2f} and "
        f"{rho[1]:+.2f}), so pair this extrinsic only with these intrinsics; to use intrinsics from elsewhere (a "
        "camera-only recording, a published calibration), calibrate the extrinsic with them: --task extrinsic "
        "--intrinsics <camchain.yaml>, or --task two_stage"
    )


def unobservable_warnings(names: list[str], covariance: np.ndarray) -> list[str]:
    """A note naming the parameters whose uncertainty could not be computed (NaN variance), with hints."""
    free = [n for n, v in zip(names, np.diag(covariance), strict=True) if not np.isfinite(v)]
    if not free:
        return []
    hints = "; ".join(dict.fromkeys(hint(n) for n in free))
    return [
        f"the data do not determine {', '.join(free)} (the information matrix is singular): their estimates are "
        f"kept but their uncertainty is unknown (NaN); {hints}"
    ]


@dataclass(frozen=True)
class Assessment:
    """What a result says about its own uncertainty (the fields every ``CalibrationResult`` gets from its
    covariance): the weak parameters, the strongest correlations, and the warnings about correlated and
    undetermined parameters."""

    weak_parameters: list[WeakParameter]
    correlations: list[Correlation]
    warnings: list[str]


def assess(names: list[str], covariance: np.ndarray, camera: CameraModel) -> Assessment:
    """``weak_parameters``, ``correlations`` and their warnings (``correlation_warnings`` then
    ``unobservable_warnings``) of the parameters ``names`` with ``covariance``."""
    found = correlations(names, covariance)
    return Assessment(
        weak_parameters(names, covariance, camera),
        found,
        correlation_warnings(found) + unobservable_warnings(names, covariance),
    )
