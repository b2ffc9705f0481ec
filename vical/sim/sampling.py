"""Per-episode sensor sampling: camera intrinsics, camera-IMU extrinsic, time offset, IMU noise and intrinsics.

The distributions mirror ``conf/sensor/paper.yaml`` (the paper's simulation settings). Every
draw goes through an explicit ``numpy.random.Generator``; the result is a ``SensorTruth`` that
travels with the recorded data.

Frames (``docs/conventions.md``): the IMU pose is sampled in the camera *body* frame
(x forward along the optical axis, y left, z up) as ``T_body_imu`` with position ``[x, y, z]``
[m] and Euler angles ``[roll, pitch, yaw]`` [rad], ``R = Rz(yaw) Ry(pitch) Rx(roll)``; the
extrinsic the calibrator estimates is ``T_cam_imu = T_cam_body @ T_body_imu``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vical.config_checks import ConfigError, from_mapping, require, require_range
from vical.data import ImuIntrinsics, ImuNoise, SensorTruth
from vical.data.imu_grade import ImuGrade
from vical.geometry import (
    CameraModel,
    CameraModelError,
    body_imu_from_cam_imu,
    cam_imu_from_body_imu,
    euler_to_matrix,
    make_transform,
)
from vical.geometry.wide_angle import WIDE_ANGLE_MODELS, invalid_coefficient
from vical.sim.products import Products

NOISE_UNITS = ("continuous", "discrete")
# The camera models the simulator draws (its coefficients' distributions); omni, omni-radtan are calibrated, not drawn.
SAMPLED_MODELS = ("radtan", "equidistant", "ds", "eucm")
INTRINSIC_STDS = (
    "accel_scale_std", "accel_misalignment_std", "gyro_scale_std", "gyro_misalignment_std", "g_sensitivity_std"
)  # fmt: skip
IMU_SAMPLING = ("average", "instant")
CAMERA_BACKENDS = ("project", "render")
# Redraws of a camera whose distortion folds over inside the image (of a product its env refuses) before giving up.
_MAX_CAMERA_DRAWS = 100
_MAX_PRODUCT_DRAWS = 100
# The paper's IMU: ImuSampling's noise and rate default to vical.data.ImuNoise's, the one place its numbers are
# written (conf/sensor/paper.yaml states them too; tests/test_config_defaults.py checks that they agree).
_PAPER_IMU = ImuNoise()


@dataclass(frozen=True)
class Normal:
    """A scalar normal distribution ``N(mean, std)`` (units of the quantity it describes)."""

    mean: float = 0.0
    std: float = 0.0

    def check(self, key: str) -> None:
        """Raise ``ConfigError`` naming ``key`` unless mean is finite and std >= 0."""
        require(bool(np.isfinite(self.mean)), f"{key}.mean", "a finite number", self.mean)
        require_range(f"{key}.std", self.std, 0.0)

    def draw(self, rng: np.random.Generator) -> float:
        return float(self.mean + self.std * rng.standard_normal())


@dataclass(frozen=True)
class CameraSampling:
    """Camera distribution.

    Attributes:
        width, height: image size [px].
        rate_hz: frame rate [Hz].
        distortion: the camera model: ``radtan`` (k1, k2 sampled; p1, p2 only with asymmetric
            distortion), ``equidistant`` (k1, k2 sampled; k3 = k4 = 0), or the wide-angle ``ds``
            (xi, alpha sampled) and ``eucm`` (alpha, beta sampled), which have no asymmetric distortion.
        hfov: horizontal field of view [rad]; pinhole models: ``fx = fy = (W/2) / tan(hfov/2)``, below pi;
            wide-angle models: the angle between the rays of the image's left and right edges (180 deg
            and beyond, as far as the drawn lens projects).
        k1, k2: radial distortion coefficients [-].
        xi, alpha, beta: wide-angle coefficients [-] (ds: xi in [-1, 1], alpha in [0, 1]; eucm: alpha in
            [0, 1], beta > 0); the defaults are near published calibrations of fisheye lenses.
        tangential_std: sigma of p1, p2 [-] (radtan, asymmetric distortion only).
        center_offset_std: sigma of the distortion-centre offset from the principal point, in
            units of the image width (x) and height (y) (asymmetric distortion only).
        line_delay: [s/row] a rolling shutter's line delay (row ``v`` exposed ``line_delay * v`` after the
            timestamp, ``docs/formats.md``), drawn per episode (at 0 and above); 0: a global shutter. Its mean
            readout (times ``height``) must be shorter than the frame interval.
    """

    width: int = 640
    height: int = 480
    rate_hz: float = 10.0
    distortion: str = "radtan"
    hfov: Normal = field(default_factory=lambda: Normal(1.0, 0.05))
    k1: Normal = field(default_factory=lambda: Normal(0.0, 0.02))
    k2: Normal = field(default_factory=lambda: Normal(0.0, 0.02))
    xi: Normal = field(default_factory=lambda: Normal(-0.2, 0.05))
    alpha: Normal = field(default_factory=lambda: Normal(0.6, 0.03))
    beta: Normal = field(default_factory=lambda: Normal(1.1, 0.05))
    tangential_std: float = 0.001
    center_offset_std: float = 0.05
    line_delay: Normal = field(default_factory=Normal)

    def __post_init__(self) -> None:
        key = "sensor.camera"
        require(isinstance(self.width, int) and self.width > 0, f"{key}.width", "a positive integer [px]", self.width)
        require(
            isinstance(self.height, int) and self.height > 0, f"{key}.height", "a positive integer [px]", self.height
        )
        require_range(f"{key}.rate_hz", self.rate_hz, 0.0, None, low_open=True)
        require(self.distortion in SAMPLED_MODELS, f"{key}.distortion", f"one of {SAMPLED_MODELS}", self.distortion)
        self.hfov.check(f"{key}.hfov")
        max_hfov = 2.0 * np.pi if self.distortion in WIDE_ANGLE_MODELS else np.pi
        require_range(f"{key}.hfov.mean", self.hfov.mean, 0.0, max_hfov, low_open=True, high_open=True)
        for name in ("k1", "k2", "xi", "alpha", "beta"):
            getattr(self, name).check(f"{key}.{name}")
        self._check_wide_angle_means(key)
        require_range(f"{key}.tangential_std", self.tangential_std, 0.0)
        require_range(f"{key}.center_offset_std", self.center_offset_std, 0.0)
        self.line_delay.check(f"{key}.line_delay")
        frame = 1.0 / self.rate_hz
        mean = self.line_delay.mean
        readout = f"[s/row] >= 0 whose readout (x {self.height} rows) is shorter than a frame ({frame:g} s)"
        require(0.0 <= mean < frame / self.height, f"{key}.line_delay.mean", readout, mean)

    def _check_wide_angle_means(self, key: str) -> None:
        """Name the coefficient (or the field of view) whose mean the lens model cannot take: draws around
        it would mostly be refused, and the redraw loop could only say that none was valid."""
        if self.distortion not in WIDE_ANGLE_MODELS:
            return
        invalid = invalid_coefficient(self.distortion, mean_coefficients(self))
        if invalid is not None:
            name, allowed = invalid
            require(False, f"{key}.{name}.mean", f"{allowed} for the {self.distortion} model", getattr(self, name).mean)
        try:
            CameraModel.from_hfov(self.hfov.mean, self.width, self.height, mean_coefficients(self), self.distortion)
        except CameraModelError as err:
            require(False, f"{key}.hfov.mean", f"a field of view the mean lens projects ({err})", self.hfov.mean)


@dataclass(frozen=True)
class ExtrinsicSampling:
    """IMU pose in the camera body frame: position [m] and Euler angles [roll, pitch, yaw] [rad]."""

    position_mean: tuple[float, float, float] = (0.06, 0.0, -0.10)
    position_std: tuple[float, float, float] = (0.01, 0.01, 0.01)
    rpy_mean: tuple[float, float, float] = (0.0, 0.0, 1.57)
    rpy_std: tuple[float, float, float] = (0.1, 0.1, 0.1)

    def __post_init__(self) -> None:
        _check_pose_distribution(self, "sensor.extrinsic")


def _check_pose_distribution(cfg: Any, key: str) -> None:
    """A pose distribution's position and Euler angle means and spreads: 3 finite numbers each, spreads >= 0."""
    for name in ("position_mean", "position_std", "rpy_mean", "rpy_std"):
        value = np.asarray(getattr(cfg, name), dtype=float)
        where = f"{key}.{name}"
        require(value.shape == (3,) and bool(np.all(np.isfinite(value))), where, "3 finite numbers", value.tolist())
        if name.endswith("std"):
            require(bool(np.all(value >= 0)), where, "non-negative", value.tolist())
        object.__setattr__(cfg, name, tuple(float(v) for v in value))


RIG_KEY = "sensor.rig[]"  # a rig camera's settings in messages, before its index is known


@dataclass(frozen=True)
class RigCameraSampling:
    """Another camera of a rig (cam1, cam2, ...), on cam0's trigger: its pose in cam0's camera (OpenCV) frame,
    position [m] (x right, y down, z along the optical axis) and Euler angles [roll, pitch, yaw] [rad] of its
    axes in cam0's; its lens is drawn from the same distribution as cam0's (``SensorSampling.camera``)."""

    position_mean: tuple[float, float, float] = (0.11, 0.0, 0.0)
    position_std: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_std: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _check_pose_distribution(self, RIG_KEY)


def _rig(cameras: Any) -> tuple[RigCameraSampling, ...]:
    """``sensor.rig`` as ``RigCameraSampling`` items (a list of mappings in a config)."""
    require(isinstance(cameras, list | tuple), "sensor.rig", "a list of the rig's other cameras ([] for none)", cameras)
    rig = []
    for index, camera in enumerate(cameras):
        key = f"sensor.rig[{index}]"
        if isinstance(camera, RigCameraSampling):
            rig.append(camera)
            continue
        require(isinstance(camera, Mapping), key, "a mapping of position_mean, position_std, rpy_mean, rpy_std",
                camera)  # fmt: skip
        try:
            rig.append(from_mapping(RigCameraSampling, camera, key))
        except ConfigError as err:  # its checks name the item generically: name it by its index
            raise ConfigError(str(err).replace(RIG_KEY, key)) from None
    return tuple(rig)


@dataclass(frozen=True)
class ImuSampling:
    """IMU rate, noise and biases.

    Attributes:
        rate_hz: sample rate [Hz].
        sampling: ``average`` (each sample is the mean of the physics readings over the sample
            interval centred on its timestamp, a real IMU's anti-aliasing) or ``instant`` (the
            physics reading at the sample instant).
        noise_units: ``continuous``: the four values are Kalibr densities (white noise
            [unit/sqrt(Hz)], bias random walk [unit/s/sqrt(Hz)]); ``discrete``: they are the
            per-sample sigmas of the white noise and of the bias increment.
        accel_noise, accel_random_walk: accelerometer noise (m/s^2 based units above).
        gyro_noise, gyro_random_walk: gyro noise (rad/s based units above).
        accel_bias_std: sigma of the initial accelerometer bias [m/s^2] (0: no bias).
        gyro_bias_std: sigma of the initial gyro bias [rad/s] (0: no bias).
        accel_scale_std, gyro_scale_std: sigma of the scale factors' departure from 1 [-].
        accel_misalignment_std: sigma of the accelerometer's axis misalignments [rad].
        gyro_misalignment_std: sigma of the gyro's axis misalignments and, unless ``gyro_rotation_std`` is set, of
            each component of its rotation from the IMU frame [rad].
        g_sensitivity_std: sigma of each entry of the gyro's g-sensitivity [(rad/s)/(m/s^2)].
            All five 0 (the default): exact axes, and nothing is drawn (``vical.data.ImuIntrinsics``).
        gyro_rotation_std: sigma of each component of the gyro's rotation from the IMU (accelerometer) frame,
            ``C_gyro_i`` [rad]; None: ``gyro_misalignment_std`` (a product's IMU grade sets 0: a grade declares no
            such term).

    The rate and the four noise values default to ``vical.data.ImuNoise``'s (the paper's IMU, continuous units).
    """

    rate_hz: float = _PAPER_IMU.rate_hz
    sampling: str = "average"
    noise_units: str = "continuous"
    accel_noise: float = _PAPER_IMU.accel_noise_density
    accel_random_walk: float = _PAPER_IMU.accel_random_walk
    gyro_noise: float = _PAPER_IMU.gyro_noise_density
    gyro_random_walk: float = _PAPER_IMU.gyro_random_walk
    accel_bias_std: float = 0.0
    gyro_bias_std: float = 0.0
    accel_scale_std: float = 0.0
    accel_misalignment_std: float = 0.0
    gyro_scale_std: float = 0.0
    gyro_misalignment_std: float = 0.0
    g_sensitivity_std: float = 0.0
    gyro_rotation_std: float | None = None

    def __post_init__(self) -> None:
        key = "sensor.imu"
        require_range(f"{key}.rate_hz", self.rate_hz, 0.0, None, low_open=True)
        require(self.sampling in IMU_SAMPLING, f"{key}.sampling", f"one of {IMU_SAMPLING}", self.sampling)
        require(self.noise_units in NOISE_UNITS, f"{key}.noise_units", f"one of {NOISE_UNITS}", self.noise_units)
        for name in ("accel_noise", "accel_random_walk", "gyro_noise", "gyro_random_walk"):
            # the datasheet declares them: the calibrator and the information state weight the IMU by them (0: an
            # IMU of infinite weight, whose every residual is exact)
            require_range(f"{key}.{name}", getattr(self, name), 0.0, low_open=True)
        require_range(f"{key}.accel_bias_std", self.accel_bias_std, 0.0)
        require_range(f"{key}.gyro_bias_std", self.gyro_bias_std, 0.0)
        for name in INTRINSIC_STDS:
            require_range(f"{key}.{name}", getattr(self, name), 0.0, 0.1)
        if self.gyro_rotation_std is not None:
            require_range(f"{key}.gyro_rotation_std", self.gyro_rotation_std, 0.0, 0.1)

    def intrinsics_spread(self) -> np.ndarray:
        """(24,) sigmas of ``ImuIntrinsics.vector(g_sensitivity=True)``."""
        rotation = self.gyro_misalignment_std if self.gyro_rotation_std is None else self.gyro_rotation_std
        return np.repeat(
            [self.accel_scale_std, self.accel_misalignment_std, self.gyro_scale_std, self.gyro_misalignment_std,
             rotation, self.g_sensitivity_std],
            [3, 3, 3, 3, 3, 9],
        )  # fmt: skip

    def grade(self) -> ImuGrade:
        """The grade the IMU's scales and misalignments are drawn from: what the simulated sensor declares."""
        return ImuGrade(self.gyro_scale_std, self.gyro_misalignment_std, self.accel_scale_std,
                        self.accel_misalignment_std)  # fmt: skip

    def made_to(self, grade: ImuGrade) -> ImuSampling:
        """This IMU with its scales and misalignments drawn from ``grade`` (``grade()`` gives it back). A grade
        declares no term for the gyro triad's rotation from the accelerometer's (C_gyro_i): neither the calibrator
        nor the information state counts one, so none is drawn (docs/sensors.md)."""
        return replace(self, gyro_scale_std=grade.gyro_scale, gyro_misalignment_std=grade.gyro_misalignment,
                       accel_scale_std=grade.accel_scale, accel_misalignment_std=grade.accel_misalignment,
                       gyro_rotation_std=0.0)  # fmt: skip

    def kalibr_noise(self) -> ImuNoise:
        """The noise model as Kalibr densities (converting per-sample sigmas when ``discrete``)."""
        if self.noise_units == "continuous":
            scale_white, scale_walk = 1.0, 1.0
        else:
            # sigma_white = density * sqrt(f); sigma_increment = random_walk * sqrt(1 / f).
            scale_white, scale_walk = 1.0 / np.sqrt(self.rate_hz), np.sqrt(self.rate_hz)
        return ImuNoise(
            accel_noise_density=self.accel_noise * scale_white,
            accel_random_walk=self.accel_random_walk * scale_walk,
            gyro_noise_density=self.gyro_noise * scale_white,
            gyro_random_walk=self.gyro_random_walk * scale_walk,
            rate_hz=float(self.rate_hz),
        )


@dataclass(frozen=True)
class SensorSampling:
    """The whole per-episode sensor distribution (``conf/sensor/*.yaml``).

    Attributes:
        camera, extrinsic, imu: see their classes.
        time_offset: Kalibr's ``timeshift_cam_imu`` [s] (``t_imu = t_cam + time_offset``).
        pixel_noise_px: sigma [px] of the Gaussian corner noise of the ``project`` backend.
        backend: camera observation backend, ``project`` (analytic) or ``render`` (MuJoCo image +
            detector).
        rig: a rig's other cameras (cam1, ...; ``RigCameraSampling``), none by default.
        products: the products drawn per episode (``vical.sim.products.Products``: lens families, boards, IMU
            grades), each episode's unit then drawn around its product's datasheet; None: one product, this.
    """

    camera: CameraSampling = field(default_factory=CameraSampling)
    extrinsic: ExtrinsicSampling = field(default_factory=ExtrinsicSampling)
    imu: ImuSampling = field(default_factory=ImuSampling)
    time_offset: Normal = field(default_factory=Normal)
    pixel_noise_px: float = 0.25
    backend: str = "project"
    rig: tuple[RigCameraSampling, ...] = ()
    products: Products | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "rig", _rig(self.rig))
        self.time_offset.check("sensor.time_offset")
        require_range("sensor.pixel_noise_px", self.pixel_noise_px, 0.0)
        require(self.backend in CAMERA_BACKENDS, "sensor.backend", f"one of {CAMERA_BACKENDS}", self.backend)
        if self.products is not None:
            self._check_lenses()

    def _check_lenses(self) -> None:
        """Every lens family projects at both ends of its field of view with ``sensor.camera``'s coefficients."""
        for index, lens in enumerate(self.products.lenses):
            key = f"sensor.products.lenses[{index}]"
            require(lens.distortion in SAMPLED_MODELS, f"{key}.distortion", f"one of {SAMPLED_MODELS}",
                    lens.distortion)  # fmt: skip
            for end in ("low", "high"):
                try:
                    _lens_camera(self.camera, lens.distortion, getattr(lens.hfov, end))
                except ConfigError as err:
                    raise ConfigError(str(err).replace("sensor.camera.hfov.mean", f"{key}.hfov.{end}")) from None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> SensorSampling:
        """Build from a plain mapping (e.g. ``OmegaConf.to_container(cfg.sensor)``); unknown keys are refused."""
        return from_mapping(cls, cfg, "sensor")


def _lens_camera(camera: CameraSampling, distortion: str, hfov: float) -> CameraSampling:
    """``camera``'s distribution for a lens family: its model, centred on its nominal field of view [rad]."""
    return replace(camera, distortion=distortion, hfov=Normal(hfov, camera.hfov.std))


# The stream of the product draws beside a sensor seed's own: products never shift the draws of a unit.
PRODUCT_STREAM = 0x50D


@dataclass(frozen=True)
class Product:
    """One episode's product.

    Attributes:
        sampling: the distribution of its units (``products`` None); its means are the product's datasheet.
        board: its printed board (``sim.board`` keys, ``vical.sim.products.replace_board``), None: the workspace's.
    """

    sampling: SensorSampling
    board: dict[str, Any] | None = None

    @functools.cached_property  # read by the env's board check, its guess and the evaluation's prior score
    def datasheet(self) -> SensorTruth:
        """What a user knows of the sensor before calibrating it: the product's nominal values."""
        return mean_sensor(self.sampling)


def draw_product(cfg: SensorSampling, sensor_seed: int, usable: Callable[[Product], bool] | None = None) -> Product:
    """The product of the episode whose sensor is drawn from ``sensor_seed`` (``cfg`` itself without products).

    Drawn from its own stream of the seed, in a fixed order (lens, board, IMU grade), so a seed gives one product
    and the unit drawn from the seed (``sample_sensor``) is independent of it. A product that ``usable`` refuses
    (the env's: a board its camera cannot detect from the workspace) is drawn again from the same stream.
    """
    products = cfg.products
    if products is None:
        return Product(cfg)
    rng = np.random.default_rng([int(sensor_seed), PRODUCT_STREAM])
    for _ in range(_MAX_PRODUCT_DRAWS):
        product = _one_product(cfg, products, rng)
        if usable is None or usable(product):
            return product
    raise ConfigError(
        f"sensor.products: {_MAX_PRODUCT_DRAWS} draws gave no product whose camera can detect its board from the "
        "workspace; widen sensor.products.boards[].square or narrow sensor.products.lenses[].hfov"
    )


def _one_product(cfg: SensorSampling, products: Products, rng: np.random.Generator) -> Product:
    lens = products.pick_lens(rng)
    board = products.pick_board(rng)
    scale = products.imu_scale(rng)
    grade = products.pick_grade(rng)  # drawn last: products without grades are those drawn before them
    camera = cfg.camera if lens is None else _lens_camera(cfg.camera, *lens)
    i = cfg.imu
    imu = replace(i, accel_noise=i.accel_noise * scale, accel_random_walk=i.accel_random_walk * scale,
                  gyro_noise=i.gyro_noise * scale, gyro_random_walk=i.gyro_random_walk * scale)  # fmt: skip
    if grade is not None:
        imu = imu.made_to(grade)
    return Product(replace(cfg, camera=camera, imu=imu, products=None), board)


def sample_camera(cfg: CameraSampling, rng: np.random.Generator, asymmetric: bool = False) -> CameraModel:
    """Draw a camera; draws whose distortion is not invertible over the image are redrawn.

    Args:
        cfg: the camera distribution.
        rng: seeded generator.
        asymmetric: also draw the distortion-centre offset and (radtan) tangential terms
            (the paper's joint task; pinhole models only); otherwise they are zero.
    """
    for _ in range(_MAX_CAMERA_DRAWS):
        camera = _draw_camera(cfg, rng, asymmetric)
        if camera is not None:
            return camera
    raise ConfigError(
        f"sensor.camera: {_MAX_CAMERA_DRAWS} draws gave no valid camera (FOV outside the model's range, "
        f"coefficients outside theirs, or distortion not invertible over the image); reduce the spread of "
        f"sensor.camera's coefficients (k1.std / k2.std now {cfg.k1.std}, {cfg.k2.std}; xi, alpha, beta .std now "
        f"{cfg.xi.std}, {cfg.alpha.std}, {cfg.beta.std}) or sensor.camera.hfov.std (now {cfg.hfov.std})"
    )


def _draw_camera(cfg: CameraSampling, rng: np.random.Generator, asymmetric: bool) -> CameraModel | None:
    if cfg.distortion in WIDE_ANGLE_MODELS:
        return _draw_wide_angle_camera(cfg, rng)
    hfov = cfg.hfov.draw(rng)
    k1, k2 = cfg.k1.draw(rng), cfg.k2.draw(rng)
    if asymmetric:
        p = cfg.tangential_std * rng.standard_normal(2) if cfg.distortion == "radtan" else np.zeros(2)
        offset = cfg.center_offset_std * rng.standard_normal(2) * [cfg.width, cfg.height]
    else:
        p, offset = np.zeros(2), np.zeros(2)
    dist = np.array([k1, k2, p[0], p[1]])
    try:
        camera = CameraModel.from_hfov(hfov, cfg.width, cfg.height, dist, cfg.distortion, offset)
        camera.check_invertible()
    except CameraModelError:
        return None
    return camera


def _draw_wide_angle_camera(cfg: CameraSampling, rng: np.random.Generator) -> CameraModel | None:
    hfov = cfg.hfov.draw(rng)
    coeffs = (
        [cfg.xi.draw(rng), cfg.alpha.draw(rng)] if cfg.distortion == "ds" else [cfg.alpha.draw(rng), cfg.beta.draw(rng)]
    )
    try:
        return CameraModel.from_hfov(hfov, cfg.width, cfg.height, coeffs, cfg.distortion)
    except CameraModelError:
        return None


def mean_coefficients(cfg: CameraSampling) -> list[float]:
    """The camera model's coefficients at the distributions' means."""
    if cfg.distortion == "ds":
        return [cfg.xi.mean, cfg.alpha.mean]
    if cfg.distortion == "eucm":
        return [cfg.alpha.mean, cfg.beta.mean]
    return [cfg.k1.mean, cfg.k2.mean, 0.0, 0.0]


def sample_pose(cfg: ExtrinsicSampling | RigCameraSampling, rng: np.random.Generator) -> np.ndarray:
    """Draw a pose (4, 4) of a pose distribution: ``T_body_imu``, the IMU in the camera body frame, of
    ``sensor.extrinsic``; ``T_cam0_cam``, another camera in cam0's frame, of a ``sensor.rig`` item."""
    position = np.asarray(cfg.position_mean) + np.asarray(cfg.position_std) * rng.standard_normal(3)
    rpy = np.asarray(cfg.rpy_mean) + np.asarray(cfg.rpy_std) * rng.standard_normal(3)
    return make_transform(euler_to_matrix(rpy), position)


def sample_sensor(cfg: SensorSampling, rng: np.random.Generator, asymmetric: bool = False) -> SensorTruth:
    """Draw one sensor (camera, extrinsic, time offset, initial IMU biases, IMU intrinsics) from ``cfg``.

    The draws happen in a fixed order, so one seed gives one sensor; the IMU intrinsics are drawn
    last and only when their spread is not zero, so configurations without them give the sensors
    they always gave.
    """
    camera = sample_camera(cfg.camera, rng, asymmetric)
    T_body_imu = sample_pose(cfg.extrinsic, rng)
    time_offset = cfg.time_offset.draw(rng)
    gyro_bias = cfg.imu.gyro_bias_std * rng.standard_normal(3)
    accel_bias = cfg.imu.accel_bias_std * rng.standard_normal(3)
    spread = cfg.imu.intrinsics_spread()
    intrinsics = ImuIntrinsics.from_vector(spread * rng.standard_normal(24)) if spread.any() else ImuIntrinsics()
    return SensorTruth(
        camera=camera,
        T_cam_imu=cam_imu_from_body_imu(T_body_imu),
        time_offset=time_offset,
        imu_noise=cfg.imu.kalibr_noise(),
        gyro_bias=gyro_bias,
        accel_bias=accel_bias,
        imu_intrinsics=intrinsics,
        line_delay=_line_delay(cfg.camera, rng),
        imu_grade=cfg.imu.grade(),
    )


def _line_delay(cfg: CameraSampling, rng: np.random.Generator) -> float:
    """[s/row] one episode's line delay: drawn (after every other draw, so sensors without a spread are unchanged)
    and held at 0 and above and below a frame's readout."""
    if cfg.line_delay.std == 0:
        return float(cfg.line_delay.mean)
    return float(np.clip(cfg.line_delay.draw(rng), 0.0, 0.99 / (cfg.rate_hz * cfg.height)))


def sample_rig(cfg: SensorSampling, rng: np.random.Generator, first: SensorTruth) -> dict[str, SensorTruth]:
    """The truths of the rig's other cameras (``cam1``, ...) beside the drawn ``first`` camera's: each its own lens
    (drawn like cam0's, centred) and its pose from ``cfg.rig``; the IMU, its noise and the time offset (one
    trigger) are the first camera's. Drawn after ``sample_sensor``'s draws: a sensor without a rig is unchanged."""
    others = {}
    for index, rig in enumerate(cfg.rig, start=1):
        camera = sample_camera(cfg.camera, rng)
        T_cam0_cam = sample_pose(rig, rng)
        others[f"cam{index}"] = replace(first, camera=camera, T_cam_imu=np.linalg.inv(T_cam0_cam) @ first.T_cam_imu)
    return others


def mean_sensor(cfg: SensorSampling) -> SensorTruth:
    """The sensor at the distributions' means (no distortion-centre offset, no biases), declaring its IMU's grade."""
    camera = CameraModel.from_hfov(
        cfg.camera.hfov.mean,
        cfg.camera.width,
        cfg.camera.height,
        mean_coefficients(cfg.camera),
        cfg.camera.distortion,
    )
    T_body_imu = make_transform(euler_to_matrix(cfg.extrinsic.rpy_mean), np.asarray(cfg.extrinsic.position_mean))
    return SensorTruth(
        camera, cam_imu_from_body_imu(T_body_imu), cfg.time_offset.mean, cfg.imu.kalibr_noise(),
        line_delay=cfg.camera.line_delay.mean, imu_grade=cfg.imu.grade(),
    )  # fmt: skip


def sensor_imu_pose(truth: SensorTruth) -> np.ndarray:
    """``T_body_imu`` (4, 4) of a sensor: the IMU pose in the camera body frame."""
    return body_imu_from_cam_imu(truth.T_cam_imu)
