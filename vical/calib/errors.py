"""The error type the calibrator raises for inputs it cannot calibrate from."""

from vical.config_checks import SettingError


class CalibrationError(ValueError):
    """Observations or settings from which no trustworthy calibration can be computed.

    The message names what is wrong (which frames, which time range, which parameter) and what
    to do about it (collect more views, rotate more, check the time stamps).
    """


class CalibrationSettingError(SettingError, CalibrationError):
    """A ``CalibrationError`` that changing one argument fixes (its message names the argument)."""
