"""Errors raised by the file readers and writers; each message names the file (and line or topic)."""

from __future__ import annotations


class FormatError(ValueError):
    """A file that cannot be read as the format it claims to be."""


class RecordingFormatError(FormatError):
    """A vical recording directory that is missing files, truncated or inconsistent."""


class KalibrFormatError(FormatError):
    """A Kalibr-style YAML file with missing or malformed keys."""


class CsvFormatError(FormatError):
    """A CSV file (EuRoC or corner observations) with malformed rows."""


class BagFormatError(FormatError):
    """A ROS bag that is corrupt or lacks the requested topics."""
