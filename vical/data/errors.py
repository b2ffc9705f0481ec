"""The error of sensor data whose shape, type or ordering is wrong."""


class DataError(ValueError):
    """Sensor data whose shape, type or ordering is wrong."""
