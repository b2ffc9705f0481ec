"""Errors raised by the file readers and writers; each message names the file (and line or topic)."""

from __future__ import annotations

from pathlib import Path

from vical.config_checks import SettingError


class FormatError(ValueError):
    """A file that cannot be read as the format it claims to be."""


class RecordingFormatError(FormatError):
    """A vical recording directory that is missing files, truncated or inconsistent."""


class KalibrFormatError(FormatError):
    """A Kalibr-style YAML file with missing or malformed keys."""


class CsvFormatError(FormatError):
    """A CSV file (EuRoC or corner observations) with malformed rows."""


class EmptyCsvError(CsvFormatError):
    """A CSV file without data rows (empty, or only a header)."""


class UnitError(SettingError, FormatError):
    """IMU readings that do not fit their declared unit; the message names the unit setting to change."""


class SourceSettingError(SettingError, FormatError):
    """A recording source that needs an argument it was not given; the message names the argument."""


class BagFormatError(FormatError):
    """A ROS bag that is corrupt or lacks the requested topics."""


class RecordingWriteError(OSError):
    """A live recording that the disk stopped taking (full, or a file-size limit); what was written before stays
    whole and readable."""


class BagTopicError(SettingError, BagFormatError):
    """A topic the bag lacks; the message names the topic argument to change."""


def read_text_file(path: Path, error: type[FormatError]) -> str:
    """The UTF-8 text of ``path``; ``error`` says which file is missing or unreadable."""
    if not path.is_file():
        raise error(f"{path} does not exist or is not a file")
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path} cannot be read as UTF-8 text (binary or corrupt?): {exc}") from exc
