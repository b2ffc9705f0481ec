"""Whether a collection can reach its tolerances in time: each group's time to tolerance at its rate of progress.

The information state predicts each parameter group's error over its tolerance, ``r`` (``vical.env.state``). Its
inverse square ``J = r^-2`` is the group's information on the tolerance's scale, and the group reaches its
tolerance when ``J`` reaches 1. ``ReachForecast`` follows ``J`` per group of the goal as a collection goes and fits
its growth over the latest part of the recording (``rate_fraction`` of it, at least ``min_window_s``) as a power of
the recording time, ``J ~ t^q`` (a least-squares slope in log-log; ``q = 1``: information at a steady rate, as a
policy that keeps collecting as it has gives; above 1 while it still finds new views, below 1 as it runs out of
them). From it, it predicts:

- the recording time each group needs, ``t J^(-1/q)`` (``needed_s``; infinite where ``J`` no longer rises: a floor
  that no amount of this motion lowers, as a lens the model cannot fit or an offset the IMU's noise hides);
- the error each group reaches at the horizon, in its own units (``achievable``);
- a verdict: once ``warmup_s`` of recording is in, a group predicted to need more than ``margin`` times the
  horizon for ``hold_s`` on end is out of reach, and the collection should stop and say so (``OutOfReach.line``)
  instead of running to its limit.

Measured on the tuning sensors (docs/evaluation.md, "Why collections do not finish"): the ratios are not monotone
(a step's motion can lose a view's information for a while), so a verdict from one step's forecast stopped runs that
would have finished; held for 10 s, 3 of the information-rate planner's 36 joint verdicts and none of its 18
intrinsic ones were wrong on 70 and 40 tuning sensors (the run met the goal within twice the horizon). A power of
time predicted the finished runs' times, from their halfway point, within 1.5x in 77 % (joint) and 90 %
(intrinsic) of them; on the first 20 sensors 83 % against a steady rate's 71 %.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from vical.config_checks import ConfigError, require_range

UNITS = {"focal": "px", "principal_point": "px", "distortion": "px", "rotation": "deg", "translation": "mm",
         "time_offset": "ms"}  # fmt: skip
NAMES = {"focal": "focal length", "principal_point": "principal point", "distortion": "distortion",
         "rotation": "extrinsic rotation", "translation": "extrinsic translation",
         "time_offset": "time offset"}  # fmt: skip
MIN_POWER = 1e-3  # information growing slower than t^MIN_POWER is not growing: the group's floor
MAX_LOG_GROWTH = 50.0  # a predicted time beyond e^50 times the recording so far is none (inf)
# What would bring each group within reach, beside a longer horizon (docs/evaluation.md: what the unfinished runs
# share, per group).
REMEDIES = {
    "focal": "a bigger board (more corners in each view)",
    "principal_point": "a bigger board (more corners in each view)",
    "distortion": "a bigger board, whose corners reach the image's corners",
    "rotation": "a lower-noise IMU (gyroscope) or a bigger board",
    "translation": "a lower-noise IMU (accelerometer) or a bigger board",
    "time_offset": "a synchronised clock (hardware-triggered camera and IMU; calibrate with --fixed-time-offset) or "
    "a lower-noise IMU",
}
# A checkerboard is detected only whole, so its corners never reach the image's borders: every unfinished
# intrinsic run of the tuning sensors had one or a double-sphere lens, and checkerboards were 3x as common among
# the unfinished joint runs as among the finished (docs/evaluation.md).
APRILGRID = "an aprilgrid instead of the checkerboard (detected in part, so its views can reach the image's borders)"
BOARD_LIMITED = ("focal", "principal_point", "distortion", "rotation", "translation")
# An IMU grade's scales and misalignments leave the extrinsic an error no more data shrink (the information
# state's considered terms): an IMU whose terms are calibrated removes it.
CALIBRATED_IMU = (
    "an IMU whose scales and misalignments are calibrated (an imu.yaml with Kalibr's scale-misalignment "
    "intrinsics, or --imu-model scale-misalignment on a long recording)"
)
GRADE_LIMITED = ("rotation", "translation")


def remedy(group: str, board_kind: str = "", imu_graded: bool = False) -> str:
    """What would bring ``group`` within reach on a sensor with a ``board_kind`` board and, where ``imu_graded``,
    an IMU grade with scale and misalignment terms, beside a longer horizon."""
    found = REMEDIES[group]
    if board_kind == "checkerboard" and group in BOARD_LIMITED:
        found = f"{APRILGRID}, or {found}"
    return f"{CALIBRATED_IMU}, or {found}" if imu_graded and group in GRADE_LIMITED else found


@dataclass(frozen=True)
class ReachSettings:
    """When a forecast calls a tolerance out of reach (measured on the tuning sensors: docs/evaluation.md).

    Attributes:
        warmup_s: [s] the recording before any verdict (the first views' progress says little of the rest).
        margin: a group is out of reach when it is predicted to need more than this times the horizon.
        rate_fraction: the latest part of the recording the rate is measured over (a least-squares slope).
        min_window_s: [s] the shortest window the rate is measured over.
        hold_s: [s] how long a group must stay out of reach before the verdict (one step's motion may lose a
            view's information for a while: the ratios are not monotone).
    """

    warmup_s: float = 15.0
    margin: float = 2.0
    rate_fraction: float = 0.5
    min_window_s: float = 5.0
    hold_s: float = 10.0

    def __post_init__(self) -> None:
        require_range("reach.warmup_s", self.warmup_s, 0.0)
        require_range("reach.margin", self.margin, 1.0)
        require_range("reach.rate_fraction", self.rate_fraction, 0.0, 1.0, low_open=True)
        require_range("reach.min_window_s", self.min_window_s, 0.0, low_open=True)
        require_range("reach.hold_s", self.hold_s, 0.0)


@dataclass(frozen=True)
class GroupForecast:
    """One group's forecast: its ratio now, the recording time it needs [s] (inf: not at this rate) and its ratio
    at the horizon (its error there over its tolerance)."""

    ratio: float
    needed_s: float
    ratio_at_horizon: float

    def as_dict(self) -> dict[str, float | None]:
        """For ``collect.yaml`` (``needed_s`` None: not at this rate)."""
        needed = None if math.isinf(self.needed_s) else round(self.needed_s, 1)
        return {"ratio": round(self.ratio, 3), "needed_s": needed, "ratio_at_horizon": round(self.ratio_at_horizon, 3)}


@dataclass(frozen=True)
class OutOfReach:
    """A tolerance the collection cannot reach within the horizon (``line``: what to tell the user).

    Attributes:
        group: the parameter group; tolerance: its tolerance (in ``unit``); achievable: the error it is predicted to
        reach at the horizon (in ``unit``); needed_s: the recording time it would need [s] (inf: none at this
        rate); horizon_s: the horizon [s]; at_s: the recording time of the verdict [s]; remedy: what would
        change it (``remedy``).
    """

    group: str
    tolerance: float
    achievable: float
    unit: str
    needed_s: float
    horizon_s: float
    at_s: float
    remedy: str

    def line(self) -> str:
        """The verdict as one line: which group, what it can reach, what would change it."""
        name = NAMES[self.group]
        need = (
            "does not shrink any more with this motion"
            if math.isinf(self.needed_s)
            else f"would need ~{self.needed_s:.0f} s of recording"
        )
        longer = "" if math.isinf(self.needed_s) else f", or a longer horizon (~{self.needed_s:.0f} s)"
        return (
            f"the {name} cannot reach its tolerance {self.tolerance:g} {self.unit} within {self.horizon_s:g} s: it "
            f"{need}, and reaches ~{self.achievable:.2g} {self.unit} in {self.horizon_s:g} s; what would change it: "
            f"{self.remedy}{longer}"
        )

    def as_dict(self) -> dict[str, object]:
        """For ``collect.yaml`` and the guide's page."""
        return {
            "group": self.group,
            "tolerance": self.tolerance,
            "achievable_at_horizon": round(self.achievable, 4),
            "unit": self.unit,
            "needed_s": None if math.isinf(self.needed_s) else round(self.needed_s, 1),
            "horizon_s": self.horizon_s,
            "decided_at_s": round(self.at_s, 1),
            "reason": self.line(),
        }


@dataclass
class ReachForecast:
    """The forecast of one collection (module doc): ``add`` each step's ratios, read ``groups`` and ``verdict``.

    Args:
        tolerances: each goal group's tolerance in its own units (``{group: value}``).
        settings: warm-up, margin and rate window.
        board_kind: the sensor's board (``Target.kind``; "" unknown): what the verdict's remedy names.
        imu_graded: the sensor's IMU declares scale and misalignment terms (a grade other than ``calibrated``): the
            remedy names a calibrated IMU first.
    """

    tolerances: Mapping[str, float]
    settings: ReachSettings = field(default_factory=ReachSettings)
    board_kind: str = ""
    imu_graded: bool = False
    _times: list[float] = field(default_factory=list)
    _info: list[dict[str, float]] = field(default_factory=list)  # J = ratio^-2 per group, per update
    _needed: list[dict[str, float]] = field(default_factory=list)  # each group's needed_s at each update

    def reset(self) -> None:
        for history in (self._times, self._info, self._needed):
            history.clear()

    def add(self, time_s: float, ratios: Mapping[str, float]) -> None:
        """The goal groups' ratios after ``time_s`` [s] of recording."""
        info = {g: float(r) ** -2.0 for g, r in ratios.items()}
        if self._times and time_s <= self._times[-1]:  # no new data: the same instant
            self._info[-1] = info
            self._needed[-1] = {g: f.needed_s for g, f in self.groups().items()}
            return
        self._times.append(float(time_s))
        self._info.append(info)
        self._needed.append({g: f.needed_s for g, f in self.groups().items()})

    @property
    def time_s(self) -> float:
        return self._times[-1] if self._times else 0.0

    def groups(self, horizon_s: float | None = None) -> dict[str, GroupForecast]:
        """Each goal group's forecast now, its ratio at ``horizon_s`` [s] (None: its ratio now); empty before two
        updates."""
        if len(self._times) < 2 or self._times[-2] <= 0.0:
            return {}
        t = self._times[-1]
        window = max(self.settings.rate_fraction * t, self.settings.min_window_s)
        first = next(k for k, s in enumerate(self._times) if s >= t - window and s > 0.0)  # log t: after the start
        first = min(first, len(self._times) - 2)  # two updates at least
        times = np.asarray(self._times[first:])
        log_t = np.log(times)
        out = {}
        for g, info in self._info[-1].items():
            power = _slope(log_t, np.log([i[g] for i in self._info[first:]]))
            out[g] = _forecast(info, power, t, horizon_s)
        return out

    def needed_s(self) -> float:
        """[s] the recording the whole goal is predicted to need (inf: some group never at this rate; nan: too
        early to say)."""
        return max(self._needed[-1].values(), default=math.nan) if self._needed else math.nan

    def outlook(self) -> str:
        """The goal's forecast for a progress line: ", goal at ~52 s of recording" ("" too early to say)."""
        needed = self.needed_s()
        if math.isnan(needed):
            return ""
        return ", goal not in sight at this rate" if math.isinf(needed) else f", goal at ~{needed:.0f} s of recording"

    def verdict(self, horizon_s: float | None) -> OutOfReach | None:
        """The group furthest out of reach within ``horizon_s`` [s] of recording, once the warm-up is over and it has
        stayed out of reach for ``hold_s``; None while all are in reach (or without a horizon)."""
        s = self.settings
        if horizon_s is None or self.time_s < s.warmup_s or not self._needed:
            return None
        late = [g for g in self._needed[-1] if self._late_for(g, s.margin * horizon_s) >= s.hold_s]
        if not late:
            return None
        groups = self.groups(horizon_s)
        group = max(late, key=lambda g: groups[g].ratio_at_horizon)
        f = groups[group]
        tolerance = float(self.tolerances[group])
        return OutOfReach(group, tolerance, tolerance * f.ratio_at_horizon, UNITS[group], f.needed_s, horizon_s,
                          self.time_s, remedy(group, self.board_kind, self.imu_graded))  # fmt: skip

    def _late_for(self, group: str, limit_s: float) -> float:
        """[s] how long ``group`` has been predicted to need more than ``limit_s`` without a break (-1: not now)."""
        since = -1.0
        for t, needed in zip(reversed(self._times), reversed(self._needed), strict=True):
            if not needed.get(group, 0.0) > limit_s:
                break
            since = self.time_s - t
        return since


def _slope(t: np.ndarray, y: np.ndarray) -> float:
    """The least-squares slope of ``y`` over ``t``."""
    dt = t - t.mean()
    return float(dt @ (y - y.mean()) / (dt @ dt))


def _forecast(info: float, power: float, t: float, horizon_s: float | None) -> GroupForecast:
    """A group's forecast from its information now (at ``t`` [s]) and the power of time it grows with (module doc)."""
    if info >= 1.0:
        needed = t
    elif power > MIN_POWER:
        needed = t * math.exp(min(-math.log(info) / power, MAX_LOG_GROWTH))
    else:
        needed = math.inf
    ratio = info**-0.5
    growth = 1.0 if horizon_s is None else (max(horizon_s, t) / t) ** max(power, 0.0)
    return GroupForecast(ratio, needed, (info * growth) ** -0.5)


class StepDuration(Protocol):
    """What a step's recording time is made of (``vical.env.lookahead``'s step timings, which import the state
    that imports this module): a motion's time [s] for a pose change, then a rest [s]."""

    rest: float

    def motion_time(self, delta: np.ndarray) -> float: ...


def check_horizon(horizon_s: float | None, key: str, reset_hold: float, timing: StepDuration) -> None:
    """``ConfigError`` naming ``key`` for a horizon [s] shorter than one step of recording: the rest at the start
    (``reset_hold``), then the shortest motion and the rest after it (``timing``)."""
    if horizon_s is None:
        return
    step = reset_hold + timing.motion_time(np.full(6, 1e-9)) + timing.rest
    if horizon_s < step:
        raise ConfigError(
            f"{key} must be at least one step of recording ({step:.2f} s: the rest at the start, the shortest "
            f"motion and the rest after it), got {horizon_s:g}; give the tolerances a horizon of seconds to minutes"
        )
