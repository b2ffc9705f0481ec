"""File formats: vical recordings, Kalibr YAML, EuRoC folders, ROS1 bags, corner CSV, image folders.

See ``docs/formats.md``. This package depends only on ``vical.geometry`` and ``vical.data``.
"""

from vical.io.errors import (
    BagFormatError,
    CsvFormatError,
    FormatError,
    KalibrFormatError,
    RecordingFormatError,
)
from vical.io.kalibr import (
    read_camchain,
    read_imu_yaml,
    read_target_yaml,
    write_camchain_imucam,
    write_imu_yaml,
    write_target_yaml,
)
from vical.io.recording import is_recording_dir, load_recording, save_recording

__all__ = [
    "BagFormatError",
    "CsvFormatError",
    "FormatError",
    "KalibrFormatError",
    "RecordingFormatError",
    "is_recording_dir",
    "load_recording",
    "read_camchain",
    "read_imu_yaml",
    "read_target_yaml",
    "save_recording",
    "write_camchain_imucam",
    "write_imu_yaml",
    "write_target_yaml",
]
