"""Lossless save/load of a ``Recording`` as a directory of ``.npz`` arrays plus ``recording.yaml``.

Layout of a recording directory (format version 1)::

    recording.yaml    format_version, target, truth (SensorTruth.to_dict), path_length [m],
                      duration [s], metadata, and for every array file its size and SHA-256
    imu.npz           t (N,) int64 [ns], gyro (N, 3) [rad/s], accel (N, 3) [m/s^2]
    frames.npz        t (M,) int64 [ns], counts (M,) int64 corners per frame,
                      corners (sum counts, 2) float64 [px], ids (sum counts,) int64
    images.npz        images (M, H, W) uint8            (only when the frames carry images)
    trajectory.npz    t (K,) int64 [ns], T_world_imu (K, 4, 4), v_world (K, 3) [m/s],
                      omega_imu (K, 3) [rad/s]          (only with a ground-truth trajectory)
    extra.npz         T_world_target (4, 4)             (only when the target pose is known)
    path.npz          t (K,) int64 [ns], length (K,) [m] end-effector path so far
                                                        (only when the path profile is known)
    frames_camN.npz   a rig's other cameras (cam1, cam2, ...), as frames.npz; images_camN.npz their images;
                      their truths under ``other_truths`` in recording.yaml

Arrays keep their dtype, so timestamps stay exact int64 ns and floats bit-exact. The directory
is written into a temporary sibling and renamed into place (``vical.io.atomic``), so a partial
recording never exists at the final path. Loading checks sizes and checksums and raises
``RecordingFormatError`` naming the damaged file.
"""

from __future__ import annotations

import hashlib
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from vical.data import CameraFrames, DataError, ImuSamples, PathProfile, Recording, SensorTruth, Target, Trajectory
from vical.io.atomic import atomic_directory
from vical.io.errors import RecordingFormatError

FORMAT_VERSION = 1
MANIFEST = "recording.yaml"


# ---------------------------------------------------------------------------------------- save
def save_recording(recording: Recording, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write ``recording`` to the directory ``path`` atomically; return the path.

    Raises ``FileExistsError`` when ``path`` exists unless ``overwrite`` is true (the old
    directory is then replaced in one rename, never left half-updated).
    """
    with atomic_directory(path, overwrite=overwrite) as tmp:
        write_recording_files(recording, tmp)
    return Path(path)


def write_recording_files(recording: Recording, directory: Path) -> None:
    """Write the files of ``recording`` into the existing empty ``directory`` (not atomic by itself).

    For callers that add files of their own to the recording's directory before it appears at its
    final path (``save_recording`` is this inside ``vical.io.atomic.atomic_directory``).
    """
    manifest = _manifest(recording)
    files = {}
    for name, arrays in _array_files(recording).items():
        files[name] = _write_npz(directory / name, arrays, compress=name.startswith("images"))
    manifest["files"] = files
    (directory / MANIFEST).write_text(yaml.safe_dump(manifest, sort_keys=False), encoding="utf-8")


def _manifest(recording: Recording) -> dict[str, Any]:
    metadata = _plain(recording.metadata)
    try:
        yaml.safe_dump(metadata)
    except yaml.YAMLError as exc:
        raise RecordingFormatError(f"recording metadata is not YAML-serialisable ({exc}); use plain types") from exc
    manifest = {
        "format_version": FORMAT_VERSION,
        "target": recording.target.to_dict(),
        "truth": None if recording.truth is None else recording.truth.to_dict(),
        "path_length": float(recording.path_length),
        "duration": float(recording.duration),
        "metadata": metadata,
    }
    if recording.other_truths:
        manifest["other_truths"] = {name: truth.to_dict() for name, truth in recording.other_truths.items()}
    return manifest


def _plain(value: Any) -> Any:
    """Metadata with numpy scalars/arrays turned into Python values (YAML-safe)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def _frame_arrays(frames: CameraFrames) -> dict[str, np.ndarray]:
    return {
        "t": frames.t,
        "counts": frames.num_detections,
        "corners": np.concatenate([np.zeros((0, 2)), *frames.corners]).astype(np.float64),
        "ids": np.concatenate([np.zeros(0, np.int64), *frames.ids]).astype(np.int64),
    }


def _array_files(rec: Recording) -> dict[str, dict[str, np.ndarray]]:
    files = {"imu.npz": {"t": rec.imu.t, "gyro": rec.imu.gyro, "accel": rec.imu.accel}}
    for name in rec.camera_names:
        suffix = "" if name == "cam0" else f"_{name}"
        frames = rec.frames_of(name)
        files[f"frames{suffix}.npz"] = _frame_arrays(frames)
        if frames.images is not None:
            files[f"images{suffix}.npz"] = {"images": frames.images}
    if rec.trajectory is not None:
        tr = rec.trajectory
        files["trajectory.npz"] = {
            "t": tr.t,
            "T_world_imu": tr.T_world_imu,
            "v_world": tr.v_world,
            "omega_imu": tr.omega_imu,
        }
    if rec.T_world_target is not None:
        files["extra.npz"] = {"T_world_target": np.asarray(rec.T_world_target, dtype=np.float64)}
    if rec.path_profile is not None:
        files["path.npz"] = {"t": rec.path_profile.t, "length": rec.path_profile.length}
    return files


def _write_npz(path: Path, arrays: dict[str, np.ndarray], compress: bool) -> dict[str, Any]:
    save = np.savez_compressed if compress else np.savez
    with open(path, "wb") as f:
        save(f, **arrays)
        f.flush()
        os.fsync(f.fileno())
    return {"bytes": path.stat().st_size, "sha256": _sha256(path)}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ---------------------------------------------------------------------------------------- load
def is_recording_dir(path: str | os.PathLike) -> bool:
    """True when ``path`` is a directory holding a ``recording.yaml`` manifest."""
    return (Path(path) / MANIFEST).is_file()


def load_recording(path: str | os.PathLike) -> Recording:
    """Read a recording written by ``save_recording``.

    Raises ``RecordingFormatError`` naming the file when the manifest or an array file is
    missing, truncated, altered or inconsistent.
    """
    root = Path(path)
    if not root.is_dir():
        raise RecordingFormatError(f"{root} is not a directory; a vical recording is a directory with {MANIFEST}")
    manifest = _read_manifest(root / MANIFEST)
    arrays = {name: _read_npz(root / name, info) for name, info in manifest["files"].items()}
    try:
        return _assemble(manifest, arrays)
    except (DataError, ValueError, KeyError, TypeError) as exc:
        raise RecordingFormatError(f"{root}: inconsistent recording content: {exc}") from exc


def _read_manifest(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise RecordingFormatError(f"{path} is missing; is {path.parent} a vical recording directory?")
    try:
        manifest = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise RecordingFormatError(f"{path} is not valid YAML (truncated or corrupt?): {exc}") from exc
    if not isinstance(manifest, dict):
        raise RecordingFormatError(f"{path} does not hold a mapping; it is truncated or not a vical manifest")
    version = manifest.get("format_version")
    if version != FORMAT_VERSION:
        raise RecordingFormatError(
            f"{path}: format_version {version!r} is not supported (this vical reads version {FORMAT_VERSION})"
        )
    for key in ("target", "files", "imu.npz", "frames.npz"):
        container = manifest["files"] if key.endswith(".npz") else manifest
        if not isinstance(container, dict) or key not in container:
            raise RecordingFormatError(f"{path}: required entry {key!r} is missing (truncated manifest?)")
    for name, info in manifest["files"].items():
        if not isinstance(info, dict) or not {"bytes", "sha256"} <= set(info):
            raise RecordingFormatError(f"{path}: files.{name} must give the file's bytes and sha256, got {info!r}")
    return manifest


def _read_npz(path: Path, info: dict[str, Any]) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise RecordingFormatError(f"{path} is missing; the recording is incomplete")
    size = path.stat().st_size
    if size != info.get("bytes"):
        raise RecordingFormatError(f"{path} has {size} bytes, the manifest says {info.get('bytes')}: truncated?")
    if _sha256(path) != info.get("sha256"):
        raise RecordingFormatError(f"{path} does not match its checksum in {MANIFEST}: the file is corrupt")
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise RecordingFormatError(f"{path} cannot be read as .npz: {exc}") from exc


def _assemble(manifest: dict[str, Any], arrays: dict[str, dict[str, np.ndarray]]) -> Recording:
    imu = arrays["imu.npz"]
    extra = arrays.get("extra.npz", {})
    path = arrays.get("path.npz")
    truth = manifest.get("truth")
    other_truths = manifest.get("other_truths") or {}
    others = [n[len("frames_") : -len(".npz")] for n in arrays if n.startswith("frames_")]
    return Recording(
        imu=ImuSamples(imu["t"], imu["gyro"], imu["accel"]),
        frames=_frames(arrays["frames.npz"], arrays.get("images.npz")),
        target=Target.from_dict(manifest["target"]),
        truth=None if truth is None else SensorTruth.from_dict(truth),
        trajectory=_trajectory(arrays.get("trajectory.npz")),
        T_world_target=extra.get("T_world_target"),
        path_length=float(manifest.get("path_length", 0.0)),
        duration=float(manifest.get("duration", 0.0)),
        metadata=manifest.get("metadata") or {},
        path_profile=None if path is None else PathProfile(path["t"], path["length"]),
        other_frames={n: _frames(arrays[f"frames_{n}.npz"], arrays.get(f"images_{n}.npz")) for n in others},
        other_truths={n: SensorTruth.from_dict(t) for n, t in other_truths.items()},
    )


def _frames(f: dict[str, np.ndarray], images: dict[str, np.ndarray] | None) -> CameraFrames:
    counts = f["counts"].astype(np.int64)
    if counts.sum() != len(f["corners"]) or len(f["corners"]) != len(f["ids"]):
        raise ValueError(f"frames.npz: counts sum to {counts.sum()} but {len(f['corners'])} corners are stored")
    splits = np.cumsum(counts)[:-1]
    corners = np.split(f["corners"], splits) if len(counts) else []
    ids = np.split(f["ids"], splits) if len(counts) else []
    return CameraFrames(f["t"], corners, ids, None if images is None else images["images"])


def _trajectory(tr: dict[str, np.ndarray] | None) -> Trajectory | None:
    if tr is None:
        return None
    return Trajectory(tr["t"], tr["T_world_imu"], tr["v_world"], tr["omega_imu"])
