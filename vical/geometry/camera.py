"""Camera models: pinhole with radial-tangential or equidistant distortion, double sphere, extended unified, unified.

Frames and units: points ``p_cam`` (N, 3) [m] are in the OpenCV/Kalibr camera frame (+z along
the optical axis, +x right, +y down in the image); pixels ``uv`` (N, 2) [px] with the centre of the
top-left pixel at (0, 0).

Projection of a point: normalised coordinates ``x = p[:2] / p[2]``, distortion ``x_d = d(x)``,
pixels ``u = fx * x_d + cx``, ``v = fy * x_d[1] + cy``. The distortion functions follow Kalibr,
OpenCV and GTSAM exactly:

- ``radtan`` (coefficients ``[k1, k2, p1, p2]``): OpenCV's model with ``k3 = 0``
  (``Cal3DS2`` in GTSAM).
- ``equidistant`` (coefficients ``[k1, k2, k3, k4]``): ``theta = atan(r)``,
  ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``,
  ``x_d = theta_d / r * x`` (OpenCV ``fisheye``, GTSAM ``Cal3Fisheye``).

Wide-angle models project rays up to and beyond 90 deg from the axis (fields of view of 180
deg and more), as Kalibr's and basalt's ``ds``, ``eucm`` and ``omni`` (``vical.geometry.wide_angle``):

- ``ds`` (coefficients ``[xi, alpha]``): the double sphere model;
- ``eucm`` (coefficients ``[alpha, beta]``): the extended unified camera model;
- ``omni`` (coefficients ``[xi]``): the unified projection ``x / (z + xi |p|)`` (Kalibr's omni-none);
- ``omni-radtan`` (coefficients ``[xi, k1, k2, p1, p2]``): the unified projection's coordinates
  distorted by ``radtan`` before the focal lengths (Kalibr's omni-radtan).

The model name sits in ``distortion`` beside the pinhole models' names so that every part of vical
handles one kind of camera description, and the model's coefficients are the ``dist`` array.
``distort`` / ``undistort`` still map between unit-depth coordinates ``p[:2] / p[2]`` and
``((u - cx) / fx, (v - cy) / fy)`` for rays in front of the camera; ``bearings`` unprojects every
pixel to a unit ray, behind the image plane too.

The simulator can also place the centre of distortion away from the principal point
(``distortion_center_offset`` [px], the paper's "asymmetric distortion"): distortion is then
applied to the normalised coordinates relative to that centre. The calibrator's models always
have the centre at the principal point, so such a lens cannot be fitted exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from vical.geometry import wide_angle
from vical.geometry.wide_angle import WIDE_ANGLE_MODELS

PINHOLE_COEFFICIENTS = {"radtan": ("k1", "k2", "p1", "p2"), "equidistant": ("k1", "k2", "k3", "k4")}
COEFFICIENT_NAMES = {
    **PINHOLE_COEFFICIENTS,
    **wide_angle.COEFFICIENTS,
    **{m: (*wide_angle.COEFFICIENTS[pr], *PINHOLE_COEFFICIENTS[d]) for m, (pr, d) in wide_angle.DISTORTED.items()},
}
DISTORTION_MODELS = {model: len(names) for model, names in COEFFICIENT_NAMES.items()}
CAMERA_MODELS = tuple(COEFFICIENT_NAMES)


class CameraModelError(ValueError):
    """Camera parameters that cannot describe a physical camera."""


@dataclass(frozen=True)
class CameraModel:
    """A camera model: pinhole with lens distortion, or a wide-angle model.

    Attributes:
        distortion: the model, one of ``CAMERA_MODELS``: ``"radtan"``, ``"equidistant"`` (pinhole with
            that distortion), ``"ds"``, ``"eucm"``, ``"omni"`` or ``"omni-radtan"`` (wide-angle models).
        width, height: image size [px].
        fx, fy: focal lengths [px]; cx, cy: principal point [px].
        dist: the model's coefficients, ``COEFFICIENT_NAMES[distortion]``: (4,) ``[k1, k2, p1, p2]`` or
            ``[k1, k2, k3, k4]``; (2,) ``[xi, alpha]`` (ds) or ``[alpha, beta]`` (eucm); (1,) ``[xi]`` (omni);
            (5,) ``[xi, k1, k2, p1, p2]`` (omni-radtan).
        distortion_center_offset: (2,) [px] centre of distortion minus principal point
            (simulation of asymmetric pinhole lenses; zero for every calibrated model).
    """

    distortion: str
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: np.ndarray | None = None
    distortion_center_offset: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        # No coefficients: the model's distortion-free ones (zeros; a pinhole-like ds / eucm start).
        dist = _neutral_coefficients(self.distortion) if self.dist is None else self.dist
        object.__setattr__(self, "dist", np.asarray(dist, dtype=float).reshape(-1).copy())
        offset = np.asarray(self.distortion_center_offset, dtype=float).reshape(-1).copy()
        object.__setattr__(self, "distortion_center_offset", offset)
        self.validate()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_hfov(
        cls,
        hfov: float,
        width: int = 640,
        height: int = 480,
        dist: np.ndarray | None = None,
        distortion: str = "radtan",
        distortion_center_offset: np.ndarray | None = None,
    ) -> CameraModel:
        """Square-pixel camera with horizontal field of view ``hfov`` [rad] across the image width.

        Pinhole models: ``fx = (W/2) / tan(hfov/2)`` (the undistorted pinhole's field of view). Wide-angle
        models: the ray ``hfov/2`` from the axis projects onto the image's left and right edges, so
        ``hfov`` may reach 180 deg and beyond (as far as the model projects). The principal point is
        the image centre ``((W-1)/2, (H-1)/2)`` in pixel-centre coordinates.
        """
        wide = distortion in WIDE_ANGLE_MODELS
        if not np.isfinite(hfov) or not 0.0 < hfov < (2.0 * np.pi if wide else np.pi):
            raise CameraModelError(f"horizontal FOV must be in (0, {'2 pi' if wide else 'pi'}) rad, got {hfov}")
        coeffs = _neutral_coefficients(distortion) if dist is None else dist
        f = (width / 2.0) / np.tan(hfov / 2.0) if not wide else _wide_edge_focal(distortion, coeffs, hfov, width)
        return cls(
            distortion=distortion,
            width=int(width),
            height=int(height),
            fx=f,
            fy=f,
            cx=(width - 1) / 2.0,
            cy=(height - 1) / 2.0,
            dist=coeffs,
            distortion_center_offset=np.zeros(2) if distortion_center_offset is None else distortion_center_offset,
        )

    def with_intrinsics(self, fx: float, fy: float, cx: float, cy: float, dist: np.ndarray) -> CameraModel:
        """Same model and image size with other parameters (centre of distortion at the principal point)."""
        return replace(
            self, fx=fx, fy=fy, cx=cx, cy=cy, dist=np.asarray(dist, float), distortion_center_offset=np.zeros(2)
        )

    # ------------------------------------------------------------------ parameters
    @property
    def intrinsics(self) -> np.ndarray:
        """``[fx, fy, cx, cy]`` [px]."""
        return np.array([self.fx, self.fy, self.cx, self.cy])

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov(self) -> float:
        """Horizontal field of view [rad] of the undistorted pinhole (``2 atan(W / (2 fx))``)."""
        return float(2.0 * np.arctan(self.width / (2.0 * self.fx)))

    def validate(self) -> None:
        """Raise ``CameraModelError`` naming the field when the parameters are impossible."""
        if self.distortion not in DISTORTION_MODELS:
            raise CameraModelError(f"camera model {self.distortion!r} unknown; use one of {list(CAMERA_MODELS)}")
        names = COEFFICIENT_NAMES[self.distortion]
        if self.dist.shape != (len(names),):
            raise CameraModelError(
                f"{self.distortion} needs {len(names)} coefficients {list(names)}, got {self.dist.tolist()}"
            )
        if self.distortion_center_offset.shape != (2,):
            raise CameraModelError("distortion_center_offset must have 2 entries [px]")
        if self.is_wide_angle and self.distortion_center_offset.any():
            raise CameraModelError(
                f"distortion_center_offset applies to the pinhole models only, not to {self.distortion}; leave it zero"
            )
        if self.width <= 0 or self.height <= 0:
            raise CameraModelError(f"image size must be positive, got {self.width} x {self.height}")
        values = {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy}
        for name, value in values.items():
            if not np.isfinite(value):
                raise CameraModelError(f"{name} must be finite, got {value}")
        if self.fx <= 0 or self.fy <= 0:
            raise CameraModelError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if not np.all(np.isfinite(self.dist)) or not np.all(np.isfinite(self.distortion_center_offset)):
            raise CameraModelError(f"distortion coefficients must be finite, got {self.dist}")
        problem = wide_angle.check_coefficients(*self.projection) if self.is_wide_angle else None
        if problem:
            raise CameraModelError(problem)

    @property
    def is_wide_angle(self) -> bool:
        """Whether the model is one of the wide-angle models (``ds``, ``eucm``, ``omni``, ``omni-radtan``) rather
        than a distorted pinhole."""
        return self.distortion in WIDE_ANGLE_MODELS

    @property
    def projection(self) -> tuple[str, np.ndarray]:
        """A wide-angle model's projection (``wide_angle.PROJECTIONS``: omni-radtan's is omni) and its coefficients
        (wide-angle models only)."""
        return _wide_angle_parts(self.distortion, self.dist)[0]

    @property
    def lens_distortion(self) -> tuple[str, np.ndarray] | None:
        """The pinhole distortion a wide-angle model applies to its projected coordinates and its coefficients
        (omni-radtan: ``radtan``, ``[k1, k2, p1, p2]``); None for ds, eucm, omni."""
        return _wide_angle_parts(self.distortion, self.dist)[1]

    def _lens_distort(self, m: np.ndarray) -> np.ndarray:
        """A wide-angle model's projected coordinates ``x / den, y / den`` (N, 2) as its lens distorts them."""
        lens = self.lens_distortion
        return m if lens is None else _DISTORTIONS[lens[0]](m, lens[1])

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """Names of the entries of ``dist``."""
        return COEFFICIENT_NAMES[self.distortion]

    # ------------------------------------------------------------------ distortion
    def _centre_shift(self) -> np.ndarray:
        return self.distortion_center_offset / np.array([self.fx, self.fy])

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates (N, 2) of undistorted normalised ``xy`` (N, 2)."""
        x = np.atleast_2d(np.asarray(xy, dtype=float))
        if self.is_wide_angle:
            p = np.hstack([x, np.ones((len(x), 1))])
            return self._lens_distort(x / wide_angle.denominator(*self.projection, p)[:, None])
        distort = _DISTORTIONS[self.distortion]
        if not self.distortion_center_offset.any():
            return distort(x, self.dist)
        shift = self._centre_shift()
        return distort(x - shift, self.dist) + shift

    def undistort(self, xy_d: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Undistorted normalised coordinates (N, 2) of distorted ``xy_d`` (N, 2) (Newton's method).

        Accurate to ~1e-12 wherever the distortion is invertible (see ``check_invertible``). Wide-angle
        models: closed form, NaN for coordinates whose ray is not in front of the camera (``bearings``).
        """
        target = np.atleast_2d(np.asarray(xy_d, dtype=float))
        if self.is_wide_angle:
            rays, _ = self._wide_angle_bearings(target, iterations)
            z = np.where(rays[:, 2] > 0, rays[:, 2], np.nan)
            return rays[:, :2] / z[:, None]
        return _inverse(self.distort, target, iterations)

    def _wide_angle_bearings(self, m_d: np.ndarray, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
        """Unit rays (N, 3) of a wide-angle model's ``((u - cx) / fx, (v - cy) / fy)`` (N, 2) and the mask of those
        it unprojects: the lens distortion undone (Newton's method), then the projection (closed form)."""
        m = m_d if self.lens_distortion is None else _inverse(self._lens_distort, m_d, iterations)
        return wide_angle.unproject(*self.projection, m)

    def check_invertible(self, margin: float = 1.15) -> None:
        """Raise ``CameraModelError`` when the distortion folds over within the image.

        The radial map must be monotonic over every radius the image (enlarged by ``margin``)
        can reach, else undistortion and image warping are ill-defined. The wide-angle projections are
        one-to-one on their valid domain by construction; omni-radtan's radtan is checked over the projected
        coordinates the image reaches.
        """
        if self.is_wide_angle and self.lens_distortion is None:
            return
        distort = self._lens_distort if self.is_wide_angle else self.distort
        corners_px = np.array([[0, 0], [self.width - 1, 0], [0, self.height - 1], [self.width - 1, self.height - 1]])
        xn = (corners_px - [self.cx, self.cy]) / [self.fx, self.fy] - self._centre_shift()
        r_max = float(np.max(np.linalg.norm(xn, axis=1))) * margin
        r = np.linspace(0.0, r_max, 400)[1:]
        xd = distort(np.stack([r, np.zeros_like(r)], axis=1) + self._centre_shift()) - self._centre_shift()
        yd = distort(np.stack([np.zeros_like(r), r], axis=1) + self._centre_shift()) - self._centre_shift()
        if np.any(np.diff(xd[:, 0]) <= 0) or np.any(np.diff(yd[:, 1]) <= 0):
            raise CameraModelError(
                f"{self.distortion} coefficients {self.dist.tolist()} are not invertible over the image "
                "(the radial map folds back); use smaller distortion coefficients"
            )

    # ------------------------------------------------------------------ projection
    def normalized_to_pixels(self, xy_d: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of distorted normalised coordinates (N, 2)."""
        xy_d = np.atleast_2d(xy_d)
        return np.stack([self.fx * xy_d[:, 0] + self.cx, self.fy * xy_d[:, 1] + self.cy], axis=1)

    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates (N, 2) of pixels (N, 2)."""
        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        return np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)

    def project(self, p_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) of camera-frame points (N, 3) [m], and a mask (N,) of the projectable points.

        Pinhole models project points in front (z > 0); the wide-angle models the points of their
        valid domain (``wide_angle.valid``), and the pixels of the others are NaN.
        """
        p = np.atleast_2d(np.asarray(p_cam, dtype=float))
        if self.is_wide_angle:
            ok = wide_angle.valid(*self.projection, p) & (np.linalg.norm(p, axis=1) > 1e-12)
            den = wide_angle.denominator(*self.projection, p)
            m = p[:, :2] / np.where(ok, den, np.nan)[:, None]
            return self.normalized_to_pixels(self._lens_distort(m)), ok
        in_front = p[:, 2] > 1e-9
        z = np.where(in_front, p[:, 2], 1.0)
        return self.normalized_to_pixels(self.distort(p[:, :2] / z[:, None])), in_front

    @property
    def parameters(self) -> np.ndarray:
        """(4 + D,) ``[fx, fy, cx, cy, *dist]``: the calibrated parameters, in ``project_jacobians`` order."""
        return np.concatenate([self.intrinsics, self.dist])

    @property
    def parameter_names(self) -> list[str]:
        """Names of ``parameters``."""
        return ["fx", "fy", "cx", "cy", *self.coefficient_names]

    def with_parameters(self, parameters: np.ndarray) -> CameraModel:
        """Same model and image size with the parameters ``[fx, fy, cx, cy, *dist]`` (4 + D,)."""
        p = np.asarray(parameters, dtype=float)
        return self.with_intrinsics(p[0], p[1], p[2], p[3], p[4:])

    def project_jacobians(self, p_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixels of camera-frame points and their analytic derivatives.

        Args:
            p_cam: (N, 3) [m] points in front of the camera (z > 0).

        Returns:
            uv (N, 2) [px]; ``d uv / d p_cam`` (N, 2, 3) [px/m]; ``d uv / d parameters`` (N, 2, 4 + D) in the
            order of ``parameters``.
        """
        if self.distortion_center_offset.any():
            raise CameraModelError("projection Jacobians need the distortion centre at the principal point")
        p = np.atleast_2d(np.asarray(p_cam, dtype=float))
        if self.is_wide_angle:
            return self._wide_angle_jacobians(p)
        inv_z = 1.0 / p[:, 2]
        x, y = p[:, 0] * inv_z, p[:, 1] * inv_z
        jacobian = _JACOBIANS[self.distortion]
        xd, yd, d_xy, d_dist = jacobian(x, y, self.dist)
        n = len(p)
        uv = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)
        d_params = np.zeros((n, 2, 8))
        d_params[:, 0, 0], d_params[:, 1, 1] = xd, yd
        d_params[:, 0, 2], d_params[:, 1, 3] = 1.0, 1.0
        d_params[:, 0, 4:] = self.fx * d_dist[:, 0]
        d_params[:, 1, 4:] = self.fy * d_dist[:, 1]
        # d(xd, yd)/d(x, y) scaled to pixels, then through x = X / Z, y = Y / Z.
        d_norm = d_xy * np.array([self.fx, self.fy])[None, :, None]
        d_point = np.empty((n, 2, 3))
        d_point[:, :, 0] = d_norm[:, :, 0] * inv_z[:, None]
        d_point[:, :, 1] = d_norm[:, :, 1] * inv_z[:, None]
        d_point[:, :, 2] = -(d_norm[:, :, 0] * x[:, None] + d_norm[:, :, 1] * y[:, None]) * inv_z[:, None]
        return uv, d_point, d_params

    def _wide_angle_jacobians(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``project_jacobians`` of ``u = fx d(m)_x + cx``, ``v = fy d(m)_y + cy`` with ``m = (x, y) / den`` and ``d``
        the lens distortion (none for ds, eucm, omni) (points in the valid domain)."""
        den, d_den, d_coeffs = wide_angle.denominator_jacobians(*self.projection, p)
        lens = self.lens_distortion
        m = p[:, :2] / den[:, None]
        # d m_i / d p = (e_i - m_i d den / d p) / den; d m / d coeffs = -m d den / d coeffs / den
        d_m = -m[:, :, None] * d_den[:, None, :]
        d_m[:, 0, 0] += 1.0
        d_m[:, 1, 1] += 1.0
        d_m /= den[:, None, None]
        d_m_coeffs = -(m / den[:, None])[:, :, None] * d_coeffs[:, None, :]
        m_d, d_lens = m, np.zeros((len(p), 2, 0))
        if lens is not None:  # chain rule through the distortion of m
            xd, yd, d_md_dm, d_lens = _JACOBIANS[lens[0]](m[:, 0], m[:, 1], lens[1])
            m_d = np.stack([xd, yd], axis=1)
            d_m, d_m_coeffs = d_md_dm @ d_m, d_md_dm @ d_m_coeffs
        f = np.array([self.fx, self.fy])
        uv = m_d * f + [self.cx, self.cy]
        d_params = np.zeros((len(p), 2, 4 + len(self.dist)))
        d_params[:, 0, 0], d_params[:, 1, 1] = m_d[:, 0], m_d[:, 1]
        d_params[:, 0, 2], d_params[:, 1, 3] = 1.0, 1.0
        d_params[:, :, 4:] = f[None, :, None] * np.concatenate([d_m_coeffs, d_lens], axis=2)
        return uv, f[None, :, None] * d_m, d_params

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Unit-depth rays (N, 3) (``[x, y, 1]``) of pixels (N, 2); NaN where the ray is not in front (z <= 0)."""
        xy = self.undistort(self.pixels_to_normalized(uv))
        return np.hstack([xy, np.ones((len(xy), 1))])

    def bearings(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit rays (N, 3) of pixels (N, 2) and a mask (N,) of the pixels the model unprojects (NaN rays elsewhere).

        Unlike ``unproject`` this covers rays at and beyond 90 deg from the axis (wide-angle models).
        """
        m = self.pixels_to_normalized(uv)
        if self.is_wide_angle:
            return self._wide_angle_bearings(m)
        xy = self.undistort(m)
        rays = np.hstack([xy, np.ones((len(xy), 1))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True), np.all(np.isfinite(rays), axis=1)

    @property
    def principal_point_in_image(self) -> bool:
        """Whether the principal point lies in the image (``0 <= cx < width``, ``0 <= cy < height``): a calibration
        that puts it outside has diverged."""
        return bool(0 <= self.cx < self.width and 0 <= self.cy < self.height)

    def in_image(self, uv: np.ndarray, border: float = 0.0) -> np.ndarray:
        """Mask (N,) of pixels inside the image, at least ``border`` [px] from its edge."""
        uv = np.atleast_2d(uv)
        return (
            (uv[:, 0] >= border - 0.5)
            & (uv[:, 0] <= self.width - 0.5 - border)
            & (uv[:, 1] >= border - 0.5)
            & (uv[:, 1] <= self.height - 0.5 - border)
        )

    def to_dict(self) -> dict:
        """Plain-python description (for YAML)."""
        return {
            "distortion": self.distortion,
            "resolution": [self.width, self.height],
            "intrinsics": [float(v) for v in self.intrinsics],
            "distortion_coeffs": [float(v) for v in self.dist],
            "distortion_center_offset": [float(v) for v in self.distortion_center_offset],
        }

    @classmethod
    def from_dict(cls, d: dict) -> CameraModel:
        """Inverse of ``to_dict``."""
        fx, fy, cx, cy = d["intrinsics"]
        return cls(
            distortion=d["distortion"],
            width=int(d["resolution"][0]),
            height=int(d["resolution"][1]),
            fx=float(fx),
            fy=float(fy),
            cx=float(cx),
            cy=float(cy),
            dist=np.asarray(d["distortion_coeffs"], dtype=float),
            distortion_center_offset=np.asarray(d.get("distortion_center_offset", [0.0, 0.0]), dtype=float),
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CameraModel):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(str(self.to_dict()))


def _neutral_coefficients(model: str) -> np.ndarray:
    """Coefficients without distortion: zeros (a pinhole; ds with ``xi = alpha = 0`` and eucm with ``alpha = 0``
    project as one); ``beta = 1`` for eucm (its spherical case)."""
    return np.array([0.0, 1.0]) if model == "eucm" else np.zeros(DISTORTION_MODELS.get(model, 4))


def _wide_angle_parts(model: str, coeffs: np.ndarray) -> tuple[tuple[str, np.ndarray], tuple[str, np.ndarray] | None]:
    """A wide-angle model's projection and its coefficients, and the distortion it applies to the projected
    coordinates with that distortion's coefficients (None for the models without: ds, eucm, omni)."""
    projection, lens = wide_angle.DISTORTED.get(model, (model, None))
    n = len(wide_angle.COEFFICIENTS[projection])
    return (projection, coeffs[:n]), None if lens is None else (lens, coeffs[n:])


def _wide_edge_focal(model: str, coeffs: np.ndarray, hfov: float, width: int) -> float:
    """[px] focal length that images the ray ``hfov / 2`` from the axis at the image edge ``W / 2`` from the centre."""
    coeffs = np.asarray(coeffs, dtype=float)
    count = DISTORTION_MODELS[model]
    if coeffs.shape != (count,):
        raise CameraModelError(f"{model} needs {count} coefficients {list(COEFFICIENT_NAMES[model])}")
    projection, lens = _wide_angle_parts(model, coeffs)
    problem = wide_angle.check_coefficients(*projection)
    if problem:
        raise CameraModelError(problem)
    edge = np.array([[np.sin(hfov / 2.0), 0.0, np.cos(hfov / 2.0)]])
    den = wide_angle.denominator(*projection, edge)[0]
    m = edge[:, :2] / den
    m_x = float((m if lens is None else _DISTORTIONS[lens[0]](m, lens[1]))[0, 0])
    if not (wide_angle.valid(*projection, edge)[0] and den > 0 and m_x > 0):
        raise CameraModelError(
            f"{model} with coefficients {coeffs.tolist()} does not project rays {hfov / 2:.3f} rad off axis"
        )
    return float((width / 2.0) / m_x)


def _inverse(distort, target: np.ndarray, iterations: int) -> np.ndarray:
    """The coordinates (N, 2) that ``distort`` maps to ``target`` (N, 2), by Newton's method from ``target``."""
    x = target.copy()
    eps = 1e-7
    for _ in range(iterations):
        r = distort(x) - target
        jx = (distort(x + [eps, 0.0]) - distort(x - [eps, 0.0])) / (2 * eps)
        jy = (distort(x + [0.0, eps]) - distort(x - [0.0, eps])) / (2 * eps)
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        det = np.where(np.abs(det) < 1e-12, 1e-12, det)
        dx = (jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det
        dy = (-jx[:, 1] * r[:, 0] + jx[:, 0] * r[:, 1]) / det
        x = x - np.stack([dx, dy], axis=1)
        if np.max(np.abs(r)) < 1e-14:
            break
    return x


def _radtan(x: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    # Python-float coefficients and preallocated output: this runs for every simulated frame.
    k1, k2, p1, p2 = coeffs.tolist()
    u, v = x[:, 0], x[:, 1]
    uu, vv, uv = u * u, v * v, u * v
    r2 = uu + vv
    radial = 1.0 + r2 * (k1 + k2 * r2)
    out = np.empty_like(x)
    out[:, 0] = u * radial + (2.0 * p1) * uv + p2 * (r2 + 2.0 * uu)
    out[:, 1] = v * radial + p1 * (r2 + 2.0 * vv) + (2.0 * p2) * uv
    return out


def _equidistant(x: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    k1, k2, k3, k4 = coeffs.tolist()
    r = np.sqrt(x[:, 0] * x[:, 0] + x[:, 1] * x[:, 1])
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    # theta_d / r -> 1 as r -> 0 (theta ~ r).
    scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0)
    return x * scale[:, None]


def _radtan_jacobian(x: np.ndarray, y: np.ndarray, coeffs: np.ndarray):
    """Distorted ``xd, yd`` (N,), ``d(xd, yd)/d(x, y)`` (N, 2, 2) and ``d(xd, yd)/d[k1, k2, p1, p2]`` (N, 2, 4)."""
    k1, k2, p1, p2 = coeffs.tolist()
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    radial = 1.0 + r2 * (k1 + k2 * r2)
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx)
    yd = y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy
    d_radial = k1 + 2.0 * k2 * r2  # d radial / d r2
    cross = 2.0 * xy * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
    d_xy = np.empty((len(x), 2, 2))
    d_xy[:, 0, 0] = radial + 2.0 * xx * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
    d_xy[:, 0, 1] = cross
    d_xy[:, 1, 0] = cross
    d_xy[:, 1, 1] = radial + 2.0 * yy * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
    d_dist = np.empty((len(x), 2, 4))
    d_dist[:, 0, 0], d_dist[:, 1, 0] = x * r2, y * r2
    d_dist[:, 0, 1], d_dist[:, 1, 1] = x * r2 * r2, y * r2 * r2
    d_dist[:, 0, 2], d_dist[:, 1, 2] = 2.0 * xy, r2 + 2.0 * yy
    d_dist[:, 0, 3], d_dist[:, 1, 3] = r2 + 2.0 * xx, 2.0 * xy
    return xd, yd, d_xy, d_dist


_SMALL_RADIUS = 1e-6  # below this the equidistant scale theta_d / r is taken from its series


def _equidistant_jacobian(x: np.ndarray, y: np.ndarray, coeffs: np.ndarray):
    """As ``_radtan_jacobian`` for ``[k1, k2, k3, k4]``: ``(xd, yd) = theta_d(atan r) / r * (x, y)``."""
    k1, k2, k3, k4 = coeffs.tolist()
    r = np.sqrt(x * x + y * y)
    small = r < _SMALL_RADIUS
    r_safe = np.where(small, 1.0, r)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    d_theta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))  # d theta_d / d theta
    # scale = theta_d / r and (d scale / d r) / r; near the axis scale = 1 + (k1 - 1/3) r^2 + O(r^4).
    scale = np.where(small, 1.0, theta_d / r_safe)
    d_scale_over_r = np.where(small, 2.0 * (k1 - 1.0 / 3.0), (d_theta_d / (1.0 + r * r) * r - theta_d) / (r_safe**3))
    d_xy = np.empty((len(x), 2, 2))
    d_xy[:, 0, 0] = scale + x * x * d_scale_over_r
    d_xy[:, 0, 1] = x * y * d_scale_over_r
    d_xy[:, 1, 0] = d_xy[:, 0, 1]
    d_xy[:, 1, 1] = scale + y * y * d_scale_over_r
    powers = np.stack([theta * t2, theta * t2**2, theta * t2**3, theta * t2**4], axis=1)
    per_r = np.where(small[:, None], np.stack([r**2, r**4, r**6, r**8], axis=1), powers / r_safe[:, None])
    d_dist = np.stack([x[:, None] * per_r, y[:, None] * per_r], axis=1)
    return x * scale, y * scale, d_xy, d_dist


_DISTORTIONS = {"radtan": _radtan, "equidistant": _equidistant}
_JACOBIANS = {"radtan": _radtan_jacobian, "equidistant": _equidistant_jacobian}
