"""Image files: grey decoding, size checks, corner detection over a sequence, image folders.

A detector is any callable ``detector(image) -> (corners (K, 2) float [px], ids (K,) int)`` taking
a (H, W) uint8 grey image and returning the target points it found, ids numbered as
``vical.data.Target`` (Kalibr) numbers them; ``vical.calib.detection.checkerboard.detect_checkerboard`` bound to
a target is one.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterable
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from vical.data import NS_PER_S, CameraFrames, Target
from vical.io.errors import FormatError
from vical.io.sample_checks import warn

ImageDetector = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")


def natural_key(name: str) -> list:
    """Sort key that orders embedded numbers by value (``img2`` before ``img10``)."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def list_images(folder: str | os.PathLike) -> list[Path]:
    """Image files directly in ``folder`` in natural name order."""
    files = [p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS]
    return sorted(files, key=lambda p: natural_key(p.name))


def read_gray(path: Path) -> np.ndarray:
    """(H, W) uint8 grey image; colour images are converted (``cv2.COLOR_BGR2GRAY``).

    Raises ``FormatError`` naming the file when it is missing, undecodable or not 8-bit.
    """
    if not path.is_file():
        raise FormatError(f"{path}: image file is missing")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise FormatError(f"{path}: cannot decode the image (truncated or not an image file)")
    return to_gray(image, str(path))


def to_gray(image: np.ndarray, where: str) -> np.ndarray:
    """(H, W) uint8 grey version of an 8-bit grey, BGR or BGRA image."""
    if image.dtype != np.uint8:
        raise FormatError(f"{where}: {image.dtype} images are not supported; convert to 8-bit grey (mono8)")
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        return cv2.cvtColor(image, code)
    return image


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a (H, W) uint8 image as lossless PNG, whatever ``path``'s extension; raise naming the file on failure."""
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: OpenCV could not encode the image as PNG")
    Path(path).write_bytes(encoded.tobytes())


def check_size(image: np.ndarray, expected: tuple[int, int] | None, where: str) -> tuple[int, int]:
    """The image's (W, H); raise ``FormatError`` when it differs from ``expected`` (W, H)."""
    size = (int(image.shape[1]), int(image.shape[0]))
    if expected is not None and size != tuple(expected):
        raise FormatError(
            f"{where}: image is {size[0]} x {size[1]} px but the sequence (or camera) is "
            f"{expected[0]} x {expected[1]} px; all images of one camera must have its resolution"
        )
    return size


def run_detector(
    detector: ImageDetector, image: np.ndarray, target: Target, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """Detections of ``detector`` on ``image`` as (K, 2) float64 and (K,) int64, validated against ``target``."""
    corners, ids = detector(image)
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    if len(corners) != len(ids):
        raise FormatError(f"{where}: the detector returned {len(corners)} corners but {len(ids)} ids")
    if len(ids) and (ids.min() < 0 or ids.max() >= target.num_points):
        raise FormatError(f"{where}: the detector returned ids outside the target's 0..{target.num_points - 1}")
    return corners, ids


def frames_from_images(
    t: np.ndarray,
    images: Iterable[tuple[str, np.ndarray]],
    target: Target,
    detector: ImageDetector | None,
    keep_images: bool,
    expected_size: tuple[int, int] | None = None,
    desc: str = "images",
) -> CameraFrames:
    """Check sizes and detect corners in a stream of images (tqdm progress), then build frames.

    Args:
        t: (M,) int64 [ns] frame timestamps.
        images: M pairs (path for messages, (H, W) uint8 image), decoded lazily to bound memory; the
            file names become the frames' ``names``.
        detector: corner detector, or None (frames without detections).
        keep_images: keep the decoded images in the returned frames.
        expected_size: (W, H) every image must have (e.g. from the camera's calibration), or None
            to require only that all images match the first.
    """
    corners, ids, kept, names = [], [], [], []
    size = expected_size
    for name, image in tqdm(images, total=len(t), desc=desc, unit="img", leave=False):
        names.append(Path(name).name)
        size = check_size(image, size, name)
        c, i = run_detector(detector, image, target, name) if detector else (np.zeros((0, 2)), np.zeros(0, int))
        corners.append(c)
        ids.append(i)
        if keep_images:
            kept.append(image)
    stacked = np.stack(kept) if keep_images and kept else None
    return CameraFrames(t, corners, ids, stacked, names)


def read_image_folder(
    folder: str | os.PathLike,
    target: Target,
    detector: ImageDetector | None = None,
    rate_hz: float = 10.0,
    t0_ns: int = 0,
    keep_images: bool = True,
) -> CameraFrames:
    """Frames from a plain folder of images (intrinsic-only calibration).

    Files with the extensions in ``IMAGE_EXTENSIONS`` are taken in natural name order; frame ``k``
    gets the timestamp ``t0_ns + round(k * 1e9 / rate_hz)`` [ns].
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FormatError(f"{folder} is not a directory of images")
    if not rate_hz > 0:
        raise FormatError(f"rate_hz must be positive, got {rate_hz}")
    paths = list_images(folder)
    if not paths:
        raise FormatError(f"{folder} holds no images (looked for {', '.join(IMAGE_EXTENSIONS)})")
    skipped = [p.name for p in folder.iterdir() if p.is_file() and p not in paths and not p.name.startswith(".")]
    if skipped:
        warn(f"{folder}: {len(skipped)} files that are not images were ignored (e.g. {skipped[0]})")
    t = t0_ns + np.round(np.arange(len(paths)) * (NS_PER_S / rate_hz)).astype(np.int64)
    images = ((str(p), read_gray(p)) for p in paths)
    return frames_from_images(t, images, target, detector, keep_images, desc=folder.name)
