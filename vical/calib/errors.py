"""The one error type the calibrator raises for inputs it cannot calibrate from."""


class CalibrationError(ValueError):
    """Observations or settings from which no trustworthy calibration can be computed.

    The message names what is wrong (which frames, which time range, which parameter) and what
    to do about it (collect more views, rotate more, check the time stamps).
    """
