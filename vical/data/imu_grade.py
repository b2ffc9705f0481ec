"""An IMU's grade: how far its scale factors and axis misalignments may be from an ideal IMU's (``ImuGrade``).

A real MEMS gyro and accelerometer read their rates and forces scaled and sheared (``vical.data.imu_model``:
``M_g``, ``M_a``, Kalibr's ``scale-misalignment`` model) by a few tenths of a percent and degree. The
``calibrated`` IMU model the solve keeps takes the readings as exact; where a recording does not determine those
terms (short windows, turns about few axes), the grade says how large they may be, and the solve counts what they
can shift the estimates by in their uncertainty (a consider-prior, ``vical.calib.solve.imu_model_error``).

The named grades (``GRADES``), each a 1-sigma of every scale factor's departure from 1 and of every misalignment:

- ``calibrated``: 0 (the readings were corrected, e.g. by a Kalibr ``scale-misalignment`` calibration; the
  simulated IMU of ``sensor=paper``);
- ``industrial``: 0.5 % and 0.2 deg: the real dev set's ADIS16448 (EuRoC), whose gyro the 30 s
  ``scale-misalignment`` solve finds at +0.87 / +0.57 / -0.22 % and 0.37 deg (within 2 of these sigmas;
  docs/calibration.md, "Real data"); the default of a real recording that declares none (``REAL_DATA_GRADE``);
- ``consumer``: 1 % and 0.5 deg: phone and hobby MEMS parts without a factory calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from vical.data.errors import DataError

# 10 % is not an IMU's imperfection but a wrong unit, a broken part or a mounting: the sigmas' upper bounds
MAX_SCALE = 0.1
MAX_MISALIGNMENT = 0.1  # [rad]


@dataclass(frozen=True)
class ImuGrade:
    """1-sigma of an IMU's scale factors and axis misalignments (Kalibr's ``scale-misalignment`` terms).

    Attributes:
        gyro_scale: of each gyro scale factor's departure from 1 [-].
        gyro_misalignment: of each gyro axis misalignment (yx, zx, zy) [rad].
        accel_scale: of each accelerometer scale factor's departure from 1 [-].
        accel_misalignment: of each accelerometer axis misalignment [rad].
    """

    gyro_scale: float = 0.0
    gyro_misalignment: float = 0.0
    accel_scale: float = 0.0
    accel_misalignment: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            limit, unit = (MAX_SCALE, "") if f.name.endswith("scale") else (MAX_MISALIGNMENT, " rad")
            if not (isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= limit):
                raise DataError(
                    f"IMU grade {f.name} must be a 1-sigma from 0 to {limit:.4g}{unit}, got {value!r}: give the "
                    "datasheet's scale-factor error as a fraction (0.005 for 0.5 %) and misalignment in radians"
                )
            object.__setattr__(self, f.name, float(value))

    @property
    def perfect(self) -> bool:
        """Whether it declares no imperfection (``calibrated``)."""
        return not any(getattr(self, f.name) for f in fields(self))

    def terms(self, sensor: str) -> tuple[float, float]:
        """The scale and misalignment 1-sigma of ``sensor`` (``gyro`` or ``accel``)."""
        return getattr(self, f"{sensor}_scale"), getattr(self, f"{sensor}_misalignment")

    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


GRADES = {
    "calibrated": ImuGrade(),
    "industrial": ImuGrade(0.005, math.radians(0.2), 0.005, math.radians(0.2)),
    "consumer": ImuGrade(0.01, math.radians(0.5), 0.01, math.radians(0.5)),
}
REAL_DATA_GRADE = "industrial"  # a real recording's IMU that declares no grade: the dev set's evidence (above)


def imu_grade(name: str) -> ImuGrade:
    """The named grade; a name that is not one is refused with the names that are."""
    if name not in GRADES:
        raise DataError(f"IMU grade {name!r} does not exist; use one of {list(GRADES)} or give its terms")
    return GRADES[name]
