"""File formats: vical recordings, Kalibr YAML, EuRoC folders, ROS1 and ROS 2 bags, corner CSV, image folders.

See ``docs/formats.md``. This package depends only on ``vical.geometry`` and ``vical.data``.
"""

from vical.io.bag import read_bag, read_bag_imu, write_bag
from vical.io.csvfiles import read_corners_csv, read_imu_csv, write_corners_csv, write_imu_csv
from vical.io.errors import (
    BagFormatError,
    CsvFormatError,
    FormatError,
    KalibrFormatError,
    RecordingFormatError,
    RecordingWriteError,
)
from vical.io.euroc import read_euroc, write_euroc
from vical.io.images import ImageDetector, read_image_folder
from vical.io.kalibr import (
    read_camchain,
    read_imu_intrinsics,
    read_imu_yaml,
    read_target_yaml,
    write_camchain_imucam,
    write_imu_yaml,
    write_target_yaml,
)
from vical.io.kalibr_chain import (
    CameraChain,
    ChainCamera,
    ImuFile,
    read_chain,
    read_imu_file,
    write_chain,
    write_imu_file,
)
from vical.io.recording import is_recording_dir, load_recording, save_recording
from vical.io.sample_checks import FormatWarning
from vical.io.sources import detect_source, open_imu, open_recording

__all__ = [
    "BagFormatError",
    "CameraChain",
    "ChainCamera",
    "CsvFormatError",
    "FormatError",
    "FormatWarning",
    "ImageDetector",
    "ImuFile",
    "KalibrFormatError",
    "RecordingFormatError",
    "RecordingWriteError",
    "detect_source",
    "is_recording_dir",
    "load_recording",
    "open_imu",
    "open_recording",
    "read_bag",
    "read_bag_imu",
    "read_camchain",
    "read_chain",
    "read_corners_csv",
    "read_euroc",
    "read_image_folder",
    "read_imu_csv",
    "read_imu_file",
    "read_imu_intrinsics",
    "read_imu_yaml",
    "read_target_yaml",
    "save_recording",
    "write_bag",
    "write_camchain_imucam",
    "write_chain",
    "write_corners_csv",
    "write_euroc",
    "write_imu_csv",
    "write_imu_file",
    "write_imu_yaml",
    "write_target_yaml",
]
