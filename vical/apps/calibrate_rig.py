"""Camera rigs in ``vical-calibrate``: which cameras, their bag topics and image sizes, and what makes a rig's
results untrustworthy (the outputs: ``vical.apps.calibrate_outputs``).

The recording's cameras (``cam0``, ``cam1``, ...: EuRoC ``camN`` folders, one bag image topic per
camera, ``frames_camN.npz`` of a recording directory) are calibrated together, or those ``--cameras``
names. The camchain written numbers the calibrated cameras ``cam0``, ``cam1``, ... in order, as
Kalibr numbers the topics it is given: ``--cameras cam1`` alone writes one ``cam0`` section whose
``rostopic`` names the recording's ``cam1`` (its bag topic, else ``/cam1/image_raw``).
"""

from __future__ import annotations

import argparse
import re

import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.result import CalibrationResult
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.plausibility import implausibilities
from vical.data import Recording
from vical.io.bag import bag_image_topics
from vical.io.kalibr_chain import CameraChain, ChainCamera

CAMERA_NAME = re.compile(r"cam(\d+)")
FRAMES_CSV = "frames.csv"  # each camera's, in its folder of the outputs
# Where each source's cameras come from, for the message that lists them.
# Where a source's cameras come from (EuRoC and corner folders refuse a camera they lack as they are read:
# vical.io.board_points.chosen_cameras).
CAMERAS_OF = {
    "bag": "one per image topic (--image-topic, or the rostopic of each camera of --intrinsics)",
    "recording": "cam0 and its frames_camN.npz",
    "corners_csv": "a corner CSV holds one camera",
    "image_folder": "an image folder holds one camera",
}


def camera_list(text: str) -> list[str]:
    """An argparse type: ``cam0,cam1`` -> the names in the rig's order (``cam0`` first)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names or not all(CAMERA_NAME.fullmatch(n) for n in names):
        raise argparse.ArgumentTypeError(f"must name cameras as Kalibr does, e.g. cam0,cam1; got {text!r}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"names a camera twice: {text!r}")
    return sorted(names, key=camera_index)


def camera_index(name: str) -> int:
    return int(CAMERA_NAME.fullmatch(name).group(1))


def topic_list(given: list[str] | None) -> list[str]:
    """The topics of ``--image-topic`` given several times and/or comma-separated, in order."""
    return [t.strip() for value in given or [] for t in value.split(",") if t.strip()]


def image_topics(given: list[str], chain: CameraChain | None, cameras: list[str] | None) -> list[str]:
    """A bag's image topics, cam0's first: ``--image-topic``'s; else each ``--intrinsics`` camera's ``rostopic``;
    else Kalibr's ``/camN/image_raw`` up to the highest camera ``--cameras`` names (``cam0`` alone by default)."""
    if given:
        return given
    if chain is not None:
        return [c.rostopic or f"/{c.name}/image_raw" for c in chain.cameras]
    count = 1 + max((camera_index(n) for n in cameras or []), default=0)
    return [f"/cam{n}/image_raw" for n in range(count)]


def check_chain_topics(bag: str, chain: CameraChain, intrinsics: str) -> None:
    """Refuse a camchain whose camera's ``rostopic`` is not an image topic of the bag (topics taken from it)."""
    present = bag_image_topics(bag)
    for camera in chain.cameras:
        topic = camera.rostopic or f"/{camera.name}/image_raw"
        if topic not in present:
            raise CalibrationError(
                f"--intrinsics {intrinsics} [{camera.name}]: rostopic {topic} is not an image topic of {bag} (it has "
                f"{', '.join(present) or 'none'}); give the bag's image topics with --image-topic, one per camera"
            )


def select_cameras(rec: Recording, requested: list[str] | None, source: str, kind: str) -> list[str]:
    """The cameras to calibrate: every one of the recording's, or those ``--cameras`` names."""
    if requested is None:
        return rec.camera_names
    missing = [n for n in requested if n not in rec.camera_names]
    if missing:
        raise CalibrationError(
            f"--cameras names {missing[0]}, but {source} has {', '.join(rec.camera_names)} ({CAMERAS_OF[kind]}); "
            "name cameras it has"
        )
    return requested


def rig_image_size(args, rec: Recording, name: str, known: ChainCamera | None) -> tuple[int, int] | None:
    """(W, H) [px] of camera ``name``'s images: as read, else ``--image-size``, else its truth's or the
    ``--intrinsics`` camera's; a ``--image-size`` or ``--intrinsics`` resolution that differs is refused."""
    images = rec.frames_of(name).images
    decoded = rec.metadata.get("image_sizes", {}).get(name) or (None if images is None else images.shape[:0:-1])
    decoded = None if decoded is None else (int(decoded[0]), int(decoded[1]))
    given = tuple(args.image_size) if args.image_size else None
    if decoded and given and decoded != given:
        raise CalibrationError(
            f"--image-size {given[0]} {given[1]} differs from {name}'s images' size {decoded[0]} x {decoded[1]} px; "
            "leave --image-size out (the images give the size)"
        )
    truth = rec.truth_of(name)
    size = decoded or given or (None if truth is None else (truth.camera.width, truth.camera.height))
    if known is not None and size is not None and (known.camera.width, known.camera.height) != size:
        raise CalibrationError(
            f"{args.intrinsics} [{name}]: resolution {known.camera.width} x {known.camera.height} px, but {name}'s "
            f"images are {size[0]} x {size[1]} px; give the camchain of this camera at this resolution"
        )
    return size or (None if known is None else (known.camera.width, known.camera.height))


def rig_problems(results: dict[str, CalibrationResult], guesses: dict[str, np.ndarray]) -> tuple[str, str] | None:
    """What makes the rig's results untrustworthy (``implausibilities``: each problem once, with the cameras that
    show it; the IMU's are every camera's) and the first camera that shows one; None when nothing does."""
    first = next(iter(results))
    problems = {
        n: implausibilities(r, guesses.get(n, nominal_T_cam_imu() if n == first else None)) for n, r in results.items()
    }
    failed = [n for n, p in problems.items() if p]
    if not failed:
        return None
    cameras: dict[str, list[str]] = {}
    for n in failed:
        for problem in problems[n]:
            cameras.setdefault(problem, []).append(n)
    return "; ".join(f"{', '.join(names)}: {problem}" for problem, names in cameras.items()), failed[0]
