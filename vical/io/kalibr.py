"""Kalibr YAML files: camchain / camchain-imucam, IMU noise, calibration targets.

Writers produce exactly the keys Kalibr's ``ConfigReader`` reads (floats where it checks for
floats), atomically. ``read_camchain`` is tolerant: besides Kalibr's ``T_cam_imu`` it accepts the
variants other VIO systems write and logs (logger ``vical.io.kalibr``) which one it found:

=====================  ======================  ===========================================
key                    written by              meaning
=====================  ======================  ===========================================
``T_cam_imu``          Kalibr                  IMU -> camera (used as is)
``T_imu_cam``          OpenVINS, Kalibr users  camera -> IMU (inverted)
``T_BS``               EuRoC ``sensor.yaml``   camera -> body = IMU (inverted)
``T_SC``               OKVIS                   camera -> sensor = IMU (inverted)
``body_T_cam0``        VINS-Mono/Fusion        camera -> body = IMU (inverted)
``timeshift_cam_imu``  Kalibr, OpenVINS        ``t_imu = t_cam + shift`` [s]
``td``                 VINS-Mono/Fusion        same sign as Kalibr [s]
=====================  ======================  ===========================================

Matrices may be nested 4 x 4 lists, flat lists of 16, or ``{rows, cols, data}`` mappings.

Camera models, as Kalibr writes them: ``camera_model: pinhole`` with ``intrinsics: [fu, fv, pu, pv]``
and a ``distortion_model`` (radtan, equidistant and their aliases); ``camera_model: ds`` (double
sphere, ``intrinsics: [xi, alpha, fu, fv, pu, pv]``) and ``camera_model: eucm`` (extended unified,
``intrinsics: [alpha, beta, fu, fv, pu, pv]``), both with ``distortion_model: none`` and
``distortion_coeffs: []``; ``camera_model: omni`` (unified, ``intrinsics: [xi, fu, fv, pu, pv]``) with
``distortion_model: none`` (vical's ``omni``) or ``radtan`` (vical's ``omni-radtan``, the
coefficients ``[k1, k2, p1, p2]`` in ``distortion_coeffs``).
"""

from __future__ import annotations

import logging
import os
import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from vical.data import ImuIntrinsics, ImuNoise, Target, TargetError
from vical.data.errors import DataError
from vical.data.imu_grade import GRADES, REAL_DATA_GRADE, ImuGrade, imu_grade
from vical.geometry import wide_angle
from vical.geometry.camera import CameraModel, CameraModelError
from vical.geometry.transforms import invert_transform
from vical.io.errors import KalibrFormatError
from vical.io.sample_checks import warn
from vical.io.yamlfile import as_floats, dump_yaml, load_mapping, require

logger = logging.getLogger(__name__)

DISTORTION_ALIASES = {
    "radtan": "radtan",
    "radial-tangential": "radtan",
    "radial_tangential": "radtan",
    "plumb_bob": "radtan",
    "equidistant": "equidistant",
    "equi": "equidistant",
    "fisheye": "equidistant",
}
WIDE_ANGLE_CAMERA_MODELS = wide_angle.PROJECTIONS  # Kalibr's names (ds, eucm, omni), vical's too
CAMERA_MODEL_NAMES = ("pinhole", *WIDE_ANGLE_CAMERA_MODELS)
# (key, whether the stored matrix is T_imu_cam and must be inverted)
EXTRINSIC_KEYS = (("T_cam_imu", False), ("T_imu_cam", True), ("T_BS", True), ("T_SC", True), ("body_T_cam0", True))
TIMESHIFT_KEYS = ("timeshift_cam_imu", "td")
# A rolling shutter's line delay [ns per image row], row 0 exposed at the image's timestamp (docs/formats.md): the key
# of Kalibr's rolling-shutter camera-IMU calibration's camchains and of the aslam camera models.
LINE_DELAY_KEY = "line_delay_nanoseconds"
# max |R R^T - I| of a stored rotation: exact below the first (float noise), rounded when written (a few
# decimals) below the second, and re-orthonormalised with a warning; beyond it, not a rotation.
EXACT_ROTATION_ERROR = 1e-9
ROUNDED_ROTATION_ERROR = 1e-4


# ------------------------------------------------------------------------------- camchain
def camera_entry(
    camera: CameraModel,
    T_cam_imu: np.ndarray | None = None,
    timeshift_cam_imu: float | None = None,
    rostopic: str = "/cam0/image_raw",
    line_delay: float | None = None,
) -> dict[str, Any]:
    """The Kalibr ``cam0`` mapping of a camera (plus extrinsic, time shift and line delay [s/row] when given)."""
    if np.any(camera.distortion_center_offset != 0):
        warnings.warn(
            "Kalibr's pinhole models have the distortion centre at the principal point; the camera's "
            f"distortion_center_offset {camera.distortion_center_offset.tolist()} px is not written",
            stacklevel=3,
        )
    entry: dict[str, Any] = {
        **kalibr_intrinsics(camera),
        "resolution": [int(camera.width), int(camera.height)],
        "rostopic": str(rostopic),
        "cam_overlaps": [],
    }
    if T_cam_imu is not None:
        entry["T_cam_imu"] = np.asarray(T_cam_imu, dtype=np.float64).reshape(4, 4).tolist()
    if timeshift_cam_imu is not None:
        entry["timeshift_cam_imu"] = float(timeshift_cam_imu)
    if line_delay is not None:
        entry[LINE_DELAY_KEY] = round(float(line_delay) * 1e9, 6)  # [ns/row] to the femtosecond, not to float noise
    return entry


def kalibr_intrinsics(camera: CameraModel) -> dict[str, Any]:
    """Kalibr's ``camera_model``, ``intrinsics``, ``distortion_model`` and ``distortion_coeffs`` of a camera."""
    if camera.is_wide_angle:
        (projection, coeffs), lens = camera.projection, camera.lens_distortion
        return {
            "camera_model": projection,
            "intrinsics": [float(v) for v in (*coeffs, *camera.intrinsics)],
            "distortion_model": "none" if lens is None else lens[0],
            "distortion_coeffs": [] if lens is None else [float(v) for v in lens[1]],
        }
    return {
        "camera_model": "pinhole",
        "intrinsics": [float(v) for v in camera.intrinsics],
        "distortion_model": camera.distortion,
        "distortion_coeffs": [float(v) for v in camera.dist],
    }


def write_camchain_imucam(
    path: str | os.PathLike,
    camera: CameraModel,
    T_cam_imu: np.ndarray | None,
    timeshift_cam_imu: float | None,
    rostopic: str = "/cam0/image_raw",
    line_delay: float | None = None,
) -> None:
    """Write a one-camera Kalibr ``camchain-imucam.yaml`` (or ``camchain.yaml`` when both are None).

    Args:
        camera: pinhole camera with radtan or equidistant distortion, or a ds, eucm, omni or omni-radtan camera.
        T_cam_imu: (4, 4) maps IMU points into the camera frame, or None.
        timeshift_cam_imu: [s] ``t_imu = t_cam + timeshift_cam_imu``, or None.
        rostopic: the image topic Kalibr associates with ``cam0``.
        line_delay: [s/row] a rolling shutter's line delay (``LINE_DELAY_KEY``), or None (a global shutter).
    """
    dump_yaml(path, {"cam0": camera_entry(camera, T_cam_imu, timeshift_cam_imu, rostopic, line_delay)})


def read_camchain(path: str | os.PathLike, camera: str = "cam0") -> tuple[CameraModel, np.ndarray | None, float | None]:
    """Camera model, ``T_cam_imu`` (4, 4) or None, and time shift [s] or None from a camchain file.

    ``camera`` selects the ``camN`` section; a file without ``camN`` sections (EuRoC's
    ``cam0/sensor.yaml``, single-camera VIO configs) is read as one flat camera section.
    """
    entry, where = _section_of(path, camera)
    return _camera_model(entry, where), _extrinsic(entry, where), _timeshift(entry, where)


def read_line_delay(path: str | os.PathLike, camera: str = "cam0") -> float | None:
    """A camchain camera's rolling-shutter line delay [s/row] (``LINE_DELAY_KEY``), or None (a global shutter)."""
    return line_delay_of(*_section_of(path, camera))


def _section_of(path: str | os.PathLike, camera: str) -> tuple[dict[str, Any], str]:
    """A camchain's ``camera`` section (a flat file's whole mapping) and where it is, for messages."""
    data = load_mapping(path, KalibrFormatError)
    if camera in data:
        entry, where = data[camera], f"{path} [{camera}]"
    elif any(isinstance(k, str) and k.startswith("cam") and k[3:].isdigit() for k in data):
        raise KalibrFormatError(f"{path}: no section {camera!r}; the file has {sorted(map(str, data))}")
    else:
        entry, where = data, str(path)
    if not isinstance(entry, dict):
        raise KalibrFormatError(f"{where} is not a mapping")
    return entry, where


def _camera_model(entry: dict[str, Any], where: str) -> CameraModel:
    model = entry.get("camera_model", "pinhole")
    if model not in CAMERA_MODEL_NAMES:
        raise KalibrFormatError(
            f"{where}: camera_model {model!r} is not supported; use one of {list(CAMERA_MODEL_NAMES)}"
        )
    width, height = _floats(entry, "resolution", 2, where)
    key = "distortion_coeffs" if "distortion_coeffs" in entry else "distortion_coefficients"
    if model in WIDE_ANGLE_CAMERA_MODELS:
        name, lens = _wide_angle_model(entry, model, key, where)
        *coeffs, fx, fy, cx, cy = _floats(entry, "intrinsics", len(wide_angle.COEFFICIENTS[model]) + 4, where)
        dist = [*coeffs, *(_floats(entry, key, 4, where) if lens else [])]
    else:
        fx, fy, cx, cy = _floats(entry, "intrinsics", 4, where)
        dist_name = str(require(entry, "distortion_model", where, KalibrFormatError))
        if dist_name not in DISTORTION_ALIASES:
            raise KalibrFormatError(
                f"{where}: distortion_model {dist_name!r} is not supported; use one of {sorted(DISTORTION_ALIASES)}"
            )
        dist, name = _floats(entry, key, 4, where), DISTORTION_ALIASES[dist_name]
    try:
        return CameraModel(name, int(width), int(height), fx, fy, cx, cy, dist)
    except CameraModelError as exc:
        raise KalibrFormatError(f"{where}: {exc}") from exc


def _wide_angle_model(entry: dict[str, Any], model: str, key: str, where: str) -> tuple[str, str | None]:
    """vical's model of a Kalibr ``ds`` / ``eucm`` / ``omni`` entry and the distortion it applies on top (None:
    ``distortion_model: none`` with no coefficients; omni also takes radtan)."""
    name = str(entry.get("distortion_model", "none"))
    lens = DISTORTION_ALIASES.get(name)
    distorted = {lens_name: m for m, (projection, lens_name) in wide_angle.DISTORTED.items() if projection == model}
    if name == "none":
        coeffs = entry.get(key)
        if coeffs is None or not np.size(coeffs):
            return model, None
    elif lens in distorted:
        return distorted[lens], lens
    allowed = " or ".join(["none (and an empty list)", *distorted])
    raise KalibrFormatError(
        f"{where}: camera_model {model} with distortion_model {name!r} and {key} {entry.get(key)!r} is not "
        f"supported; vical reads camera_model {model} with distortion_model {allowed}"
    )


def _floats(entry: dict[str, Any], key: str, n: int, where: str) -> np.ndarray:
    return as_floats(require(entry, key, where, KalibrFormatError), n, key, where, KalibrFormatError)


def _extrinsic(entry: dict[str, Any], where: str) -> np.ndarray | None:
    found = [(key, inverted) for key, inverted in EXTRINSIC_KEYS if key in entry]
    if not found:
        logger.info("%s: no camera-IMU extrinsic (looked for %s)", where, [k for k, _ in EXTRINSIC_KEYS])
        return None
    if len(found) > 1:
        raise KalibrFormatError(f"{where}: several extrinsics {[k for k, _ in found]}; keep exactly one")
    key, inverted = found[0]
    T = parse_transform(entry[key], key, where)
    logger.info("%s: camera-IMU extrinsic from %r%s", where, key, " (camera -> IMU, inverted)" if inverted else "")
    return invert_transform(T) if inverted else T


def parse_transform(value: Any, key: str, where: str) -> np.ndarray:
    """(4, 4) rigid transform from a nested list, a flat list of 16 or a ``{rows, cols, data}`` mapping."""
    if isinstance(value, dict):
        value = require(value, "data", f"{where} [{key}]", KalibrFormatError)
    T = as_floats(value, 16, key, where, KalibrFormatError).reshape(4, 4)
    R = T[:3, :3]
    error = float(np.abs(R @ R.T - np.eye(3)).max())
    if not np.allclose(T[3], [0, 0, 0, 1]) or error >= ROUNDED_ROTATION_ERROR:
        raise KalibrFormatError(
            f"{where}: {key} is not a rigid transform (rotation block not orthonormal: |R R^T - I| = {error:.1e}, "
            f"beyond the {ROUNDED_ROTATION_ERROR:g} of a rotation written with a few decimals)"
        )
    if np.linalg.det(R) < 0:
        raise KalibrFormatError(f"{where}: {key} has a reflection (det < 0), not a rotation")
    if error > EXACT_ROTATION_ERROR:
        warn(f"{where}: {key} is {error:.1e} from orthonormal (rounded when written); using the nearest rotation")
        U, _, Vt = np.linalg.svd(R)
        T = T.copy()
        T[:3, :3] = U @ Vt
    return T


def _timeshift(entry: dict[str, Any], where: str) -> float | None:
    for key in TIMESHIFT_KEYS:
        if key in entry:
            value = _floats(entry, key, 1, where)[0]
            logger.info("%s: camera-IMU time shift from %r (t_imu = t_cam + shift)", where, key)
            return float(value)
    return None


def line_delay_of(entry: dict[str, Any], where: str) -> float | None:
    """[s/row] a camera section's line delay (``LINE_DELAY_KEY``, ns/row), or None; refused when negative."""
    if LINE_DELAY_KEY not in entry:
        return None
    value = float(_floats(entry, LINE_DELAY_KEY, 1, where)[0])
    if value < 0:
        raise KalibrFormatError(
            f"{where}: {LINE_DELAY_KEY} must be >= 0 (ns from one image row's exposure to the next; 0: a global "
            f"shutter), got {value:g}"
        )
    return value * 1e-9


# ------------------------------------------------------------------------------- IMU
def write_imu_yaml(
    path: str | os.PathLike,
    noise: ImuNoise,
    rostopic: str = "/imu0",
    comment: str | None = None,
    intrinsics: ImuIntrinsics | None = None,
    grade: ImuGrade | None = None,
) -> None:
    """Write Kalibr's IMU configuration (``imu.yaml``) for ``noise``, atomically, headed by ``comment`` (``#`` lines).

    Units: noise densities in rad/s/sqrt(Hz) (gyro) and m/s^2/sqrt(Hz) (accel), random walks in
    rad/s^2/sqrt(Hz) and m/s^3/sqrt(Hz), ``update_rate`` in Hz. With ``intrinsics``, also Kalibr's
    ``scale-misalignment`` keys: ``model``, ``accelerometers: {M}``, ``gyroscopes: {M, A, C_gyro_i}``
    (``vical.data.ImuIntrinsics``; ``A`` in (rad/s)/(m/s^2)). With ``grade``, vical's grade keys
    (``GRADE_KEYS``, which Kalibr does not read).
    """
    data: dict[str, Any] = {
        "accelerometer_noise_density": float(noise.accel_noise_density),
        "accelerometer_random_walk": float(noise.accel_random_walk),
        "gyroscope_noise_density": float(noise.gyro_noise_density),
        "gyroscope_random_walk": float(noise.gyro_random_walk),
        "update_rate": float(noise.rate_hz),
        "rostopic": str(rostopic),
    }
    if intrinsics is not None:
        data["model"] = "scale-misalignment"
        data["accelerometers"] = {"M": intrinsics.M_accel.tolist()}
        data["gyroscopes"] = {
            "M": intrinsics.M_gyro.tolist(), "A": intrinsics.A_gyro.tolist(), "C_gyro_i": intrinsics.C_gyro_i.tolist()
        }  # fmt: skip
    if grade is not None:
        data.update(_grade_entries(grade))
    dump_yaml(path, data, comment=comment)


def _grade_entries(grade: ImuGrade) -> dict[str, Any]:
    """An imu.yaml's grade keys: the grade's name where it is a named one (what a person reads and edits), else
    every term."""
    name = next((name for name, named in GRADES.items() if named == grade), None)
    if name is not None:
        return {GRADE_NAME_KEY: name}
    return {key: getattr(grade, term) for term, key in GRADE_KEYS.items()}


# vical's keys of an imu.yaml's grade (vical.data.imu_grade; Kalibr ignores them): a named grade, then any term
# that differs from it (1-sigma; scales as a fraction, misalignments in rad).
GRADE_NAME_KEY = "imu_grade"
GRADE_KEYS = {
    "gyro_scale": "gyroscope_scale_sigma",
    "gyro_misalignment": "gyroscope_misalignment_sigma",
    "accel_scale": "accelerometer_scale_sigma",
    "accel_misalignment": "accelerometer_misalignment_sigma",
}


def read_imu_grade(path: str | os.PathLike) -> ImuGrade | None:
    """The grade an IMU file declares (``GRADE_NAME_KEY``, ``GRADE_KEYS``; flat or ``imu0`` section), or None
    where it declares none. Terms it does not give are the named grade's, else ``REAL_DATA_GRADE``'s."""
    data = load_mapping(path, KalibrFormatError)
    entry, where = (data["imu0"], f"{path} [imu0]") if isinstance(data.get("imu0"), dict) else (data, str(path))
    given = {name: key for name, key in GRADE_KEYS.items() if key in entry}
    if GRADE_NAME_KEY not in entry and not given:
        return None
    try:
        base = imu_grade(str(entry.get(GRADE_NAME_KEY, REAL_DATA_GRADE)))
    except DataError as exc:
        raise KalibrFormatError(f"{where}: {GRADE_NAME_KEY}: {exc}") from exc
    terms = {name: float(as_floats(entry[key], 1, key, where, KalibrFormatError)[0]) for name, key in given.items()}
    for name, key in given.items():
        try:
            ImuGrade(**{name: terms[name]})  # refused by its own key
        except DataError as exc:
            raise KalibrFormatError(f"{where}: {key}: {exc}") from exc
    return replace(base, **terms)


INTRINSIC_KEYS = (("accelerometers", "M"), ("gyroscopes", "M"), ("gyroscopes", "A"), ("gyroscopes", "C_gyro_i"))


def read_imu_intrinsics(path: str | os.PathLike) -> ImuIntrinsics | None:
    """The IMU intrinsics of a Kalibr IMU file (``model: scale-misalignment``), or None: no model, ``calibrated``,
    or another Kalibr or OpenVINS model (``kalibr``, ``rpng``, ...) whose intrinsics are those of an ideal IMU.

    Reads the flat file or Kalibr's result / OpenVINS's ``kalibr_imu_chain.yaml`` (``imu0`` section);
    refuses unknown models and intrinsics vical would not apply, by key (``refuse_imu_intrinsics``), and
    scale-misalignment matrices that are not Kalibr's (``M`` lower triangular with a positive diagonal,
    ``C_gyro_i`` a rotation).
    """
    data = load_mapping(path, KalibrFormatError)
    entry, where = (data["imu0"], f"{path} [imu0]") if isinstance(data.get("imu0"), dict) else (data, str(path))
    refuse_imu_intrinsics(entry, where)
    if entry.get("model", "calibrated") != "scale-misalignment":
        return None
    matrices = []
    for group, key in INTRINSIC_KEYS:
        section = require(entry, group, where, KalibrFormatError)
        if not isinstance(section, dict):
            raise KalibrFormatError(f"{where}: {group} must be a mapping with {key}")
        matrices.append(as_floats(require(section, key, f"{where} [{group}]", KalibrFormatError), 9, key, where,
                                  KalibrFormatError).reshape(3, 3))  # fmt: skip
    M_accel, M_gyro, A_gyro, C_gyro_i = matrices
    try:
        return ImuIntrinsics(M_accel, M_gyro, C_gyro_i, A_gyro)
    except ValueError as exc:
        raise KalibrFormatError(f"{where}: {exc}") from exc


def read_imu_yaml(path: str | os.PathLike) -> ImuNoise:
    """``ImuNoise`` from a Kalibr IMU file, Kalibr's ``imu-*.yaml`` result (``imu0`` section) or EuRoC's
    ``imu0/sensor.yaml`` (``rate_hz`` instead of ``update_rate``).

    IMU intrinsics that vical would not apply (``refuse_imu_intrinsics``) are refused.
    """
    data = load_mapping(path, KalibrFormatError)
    entry, where = (data["imu0"], f"{path} [imu0]") if isinstance(data.get("imu0"), dict) else (data, str(path))
    refuse_imu_intrinsics(entry, where)
    return imu_noise_of(entry, where)


def imu_noise_of(entry: dict[str, Any], where: str) -> ImuNoise:
    """``ImuNoise`` from an IMU section's noise keys and rate (``update_rate`` or ``rate_hz``)."""
    rate_key = "update_rate" if "update_rate" in entry else "rate_hz"
    keys = {
        "accel_noise_density": "accelerometer_noise_density",
        "accel_random_walk": "accelerometer_random_walk",
        "gyro_noise_density": "gyroscope_noise_density",
        "gyro_random_walk": "gyroscope_random_walk",
        "rate_hz": rate_key,
    }
    values = {}
    for field_name, key in keys.items():
        value = _floats(entry, key, 1, where)[0]
        if not (np.isfinite(value) and value > 0):
            raise KalibrFormatError(f"{where}: {key} must be a positive finite number, got {value}")
        values[field_name] = float(value)
    return ImuNoise(**values)


# IMU models of Kalibr's result files and OpenVINS's configs; vical applies scale-misalignment's intrinsics
# (read_imu_intrinsics) and accepts the others with an ideal IMU's.
KNOWN_IMU_MODELS = ("calibrated", "kalibr", "rpng", "scale-misalignment", "scale-misalignment-size-effect")
# (path of the key, the value of an ideal IMU): Kalibr's scale-misalignment model, then OpenVINS's.
IDEAL_IMU = (
    (("accelerometers", "M"), np.eye(3)),
    (("gyroscopes", "M"), np.eye(3)),
    (("gyroscopes", "A"), np.zeros((3, 3))),
    (("gyroscopes", "C_gyro_i"), np.eye(3)),
    (("accelerometers", "rx_i"), np.zeros(3)),
    (("accelerometers", "ry_i"), np.zeros(3)),
    (("accelerometers", "rz_i"), np.zeros(3)),
    (("Tw",), np.eye(3)),
    (("Ta",), np.eye(3)),
    (("Tg",), np.zeros((3, 3))),
    (("R_IMUtoGYRO",), np.eye(3)),
    (("R_IMUtoACC",), np.eye(3)),
    (("T_i_b",), np.eye(4)),
    (("time_offset",), np.zeros(1)),
)


def refuse_imu_intrinsics(entry: dict[str, Any], where: str) -> None:
    """Refuse IMU intrinsics vical does not apply (all but Kalibr's ``scale-misalignment`` model's, which
    ``read_imu_intrinsics`` reads): vical's solve would use the raw samples uncorrected.

    ``T_i_b`` (the IMU in the body frame) and ``time_offset`` (to the reference IMU) describe a second
    IMU of a Kalibr chain; vical calibrates one IMU, the reference (identity, 0).
    """
    model = entry.get("model", "calibrated")
    if model not in KNOWN_IMU_MODELS:
        raise KalibrFormatError(
            f"{where}: model {model!r} is not a Kalibr or OpenVINS IMU model {list(KNOWN_IMU_MODELS)}"
        )
    applied = set(INTRINSIC_KEYS) if model == "scale-misalignment" else set()  # read_imu_intrinsics reads them
    for path, ideal in IDEAL_IMU:
        if path in applied:
            continue
        value: Any = entry
        for key in path:
            value = value.get(key) if isinstance(value, dict) else None
        if value is None:
            continue
        name = ".".join(path)
        values = as_floats(value, ideal.size, name, where, KalibrFormatError).reshape(ideal.shape)
        if not np.allclose(values, ideal, rtol=0.0, atol=1e-12):
            what = "the reference IMU's" if path[0] in ("T_i_b", "time_offset") else "an ideal IMU's"
            raise KalibrFormatError(
                f"{where}: {name} differs from {what} ({'identity' if ideal.any() else 'zero'}); vical applies IMU "
                "intrinsics of Kalibr's model: scale-misalignment only (no size effect, OpenVINS matrices or "
                f"second-IMU pose) and would use the samples uncorrected: correct the samples with {name} first, or "
                "give an imu.yaml without it"
            )


# ------------------------------------------------------------------------------- targets
def write_target_yaml(path: str | os.PathLike, target: Target) -> None:
    """Write Kalibr's target file (``checkerboard`` or ``aprilgrid``) for ``target``, atomically.

    An aprilgrid ``Target`` stores ``tagRows = rows``, ``tagCols = cols``, ``tagSize = row_spacing``
    [m] and ``tagSpacing = tag_spacing`` (gap / tag size).
    """
    if target.kind == "checkerboard":
        data = {
            "target_type": "checkerboard",
            "targetRows": int(target.rows),
            "targetCols": int(target.cols),
            "rowSpacingMeters": float(target.row_spacing),
            "colSpacingMeters": float(target.col_spacing),
        }
    else:
        data = {
            "target_type": "aprilgrid",
            "tagRows": int(target.rows),
            "tagCols": int(target.cols),
            "tagSize": float(target.row_spacing),
            "tagSpacing": float(target.tag_spacing),
        }
    dump_yaml(path, data)


def read_target_yaml(path: str | os.PathLike) -> Target:
    """``Target`` from a Kalibr target file (``checkerboard`` or ``aprilgrid``)."""
    data = load_mapping(path, KalibrFormatError)
    where = str(path)
    kind = require(data, "target_type", where, KalibrFormatError)
    try:
        if kind == "checkerboard":
            rows, cols = _count(data, "targetRows", where), _count(data, "targetCols", where)
            row_sp, col_sp = _length(data, "rowSpacingMeters", where), _length(data, "colSpacingMeters", where)
            return Target("checkerboard", rows, cols, row_sp, col_sp)
        if kind == "aprilgrid":
            _refuse_code_offset(data, where)
            size = _length(data, "tagSize", where)
            spacing = _length(data, "tagSpacing", where)
            rows, cols = _count(data, "tagRows", where), _count(data, "tagCols", where)
            return Target("aprilgrid", rows, cols, size, size, spacing)
    except TargetError as exc:
        raise KalibrFormatError(f"{where}: {exc}") from exc
    raise KalibrFormatError(f"{where}: target_type {kind!r} is not supported; use 'checkerboard' or 'aprilgrid'")


def _refuse_code_offset(data: dict[str, Any], where: str) -> None:
    """vical numbers an aprilgrid's tags from 0; a grid printed with other tag codes would be misread."""
    offset = data.get("codeOffset", 0)
    if offset != 0:
        raise KalibrFormatError(
            f"{where}: codeOffset {offset!r} is not supported (vical reads aprilgrids whose tags are numbered "
            "from 0, Kalibr's default); print a grid with codeOffset 0"
        )


def _count(data: dict[str, Any], key: str, where: str) -> int:
    value = require(data, key, where, KalibrFormatError)
    if isinstance(value, bool) or not isinstance(value, int):
        raise KalibrFormatError(f"{where}: {key} must be an integer, got {value!r}")
    return value


def _length(data: dict[str, Any], key: str, where: str) -> float:
    value = _floats(data, key, 1, where)[0]
    if value <= 0:
        raise KalibrFormatError(f"{where}: {key} must be positive, got {value}")
    if (key.endswith("Meters") or key == "tagSize") and value > 5.0:
        raise KalibrFormatError(f"{where}: {key} = {value} m is implausibly large; is it in mm? Give meters")
    return float(value)
