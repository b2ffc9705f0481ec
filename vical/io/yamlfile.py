"""Reading YAML mappings with errors that name the file, line and key."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from vical.io.atomic import write_text_atomic
from vical.io.errors import FormatError, read_text_file


def load_mapping(path: str | os.PathLike, error: type[FormatError]) -> dict[str, Any]:
    """The top-level mapping of the YAML file ``path``; ``error`` names the file and line on failure.

    OpenCV ``FileStorage`` files (``%YAML:1.0`` header, ``!!opencv-matrix`` tags, as VINS-Mono
    writes) are accepted: the header is skipped and the tagged matrices read as plain mappings.
    """
    path = Path(path)
    text = read_text_file(path, error)
    if text.startswith("%YAML:1.0"):
        text = text.split("\n", 1)[1] if "\n" in text else ""
    try:
        data = yaml.load(text, Loader=_TolerantLoader)
    except yaml.YAMLError as exc:
        raise error(f"{path} is not valid YAML (truncated or corrupt?): {exc}") from exc
    if not isinstance(data, dict):
        raise error(f"{path} does not hold a YAML mapping (got {type(data).__name__}); is the file truncated?")
    return data


class _TolerantLoader(yaml.SafeLoader):
    """SafeLoader that reads OpenCV's ``!!opencv-matrix`` tags as plain mappings."""


_TolerantLoader.add_constructor(
    "tag:yaml.org,2002:opencv-matrix", lambda loader, node: loader.construct_mapping(node, deep=True)
)


def dump_yaml(
    path: str | os.PathLike, data: dict[str, Any], *, header: str | None = None, comment: str | None = None
) -> None:
    """Write ``data`` as block YAML with inline lists (Kalibr's look), atomically; ``header`` (e.g. OpenCV's
    ``%YAML:1.0``) becomes the first line, then ``comment``'s lines as ``# `` comments.

    The text is one that OpenCV's ``cv::FileStorage`` reads too (``_FileStorageDumper``); numpy numbers and
    arrays are written as Python's (floats in their shortest round-tripping digits)."""
    lines = [] if header is None else [f"{header}\n"]
    lines += [f"# {line}".rstrip() + "\n" for line in comment.splitlines()] if comment else []
    text = yaml.dump(data, Dumper=_FileStorageDumper, sort_keys=False, default_flow_style=None, width=_NO_WRAPPING)
    write_text_atomic(path, "".join(lines) + text)


# cv::FileStorage refuses a string continued on the next line ("Invalid character"): every value stays on its line.
_NO_WRAPPING = 2**31 - 1


class _FileStorageDumper(yaml.SafeDumper):
    """SafeDumper whose text ``cv::FileStorage`` reads (OpenVINS reads its files with it): block mappings,
    sequences of scalars inline ([..]), no anchors.

    cv::FileStorage takes a block sequence only indented under its key (``T_imu_cam:`` then ``  - [..]``);
    PyYAML writes it flush with the key ("indentless"), which OpenCV refuses ("Incorrect indentation").
    """

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)

    def represent_mapping(self, tag: str, mapping: Any, flow_style: bool | None = None) -> yaml.MappingNode:
        # Block mappings only: cv::FileStorage refuses a file that is one {..} mapping ("Invalid or unsupported
        # syntax"), which PyYAML writes for a mapping of scalars (a flat imu.yaml, a target.yaml).
        return super().represent_mapping(tag, mapping, flow_style=False)

    def ignore_aliases(self, data: Any) -> bool:
        return True  # cv::FileStorage reads no anchors (&id001): an object met twice is written twice


# numpy's numbers and arrays as Python's: SafeDumper refuses them (float64, a float subclass, included).
_FileStorageDumper.add_multi_representer(np.floating, lambda dumper, v: dumper.represent_float(float(v)))
_FileStorageDumper.add_multi_representer(np.integer, lambda dumper, v: dumper.represent_int(int(v)))
_FileStorageDumper.add_multi_representer(np.bool_, lambda dumper, v: dumper.represent_bool(bool(v)))
_FileStorageDumper.add_multi_representer(np.ndarray, lambda dumper, v: dumper.represent_list(v.tolist()))


def require(d: dict[str, Any], key: str, where: str, error: type[FormatError]) -> Any:
    """``d[key]``, or ``error`` naming ``where`` (file and section) and the missing key."""
    if key not in d:
        raise error(f"{where}: required key {key!r} is missing (found keys: {sorted(d)})")
    return d[key]


def as_floats(value: Any, n: int, key: str, where: str, error: type[FormatError]) -> np.ndarray:
    """``value`` as a finite float64 array of ``n`` entries, else ``error`` naming the key."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise error(f"{where}: {key} must be a list of {n} numbers, got {value!r}") from exc
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise error(f"{where}: {key} must hold {n} finite numbers, got {value!r}")
    return arr
