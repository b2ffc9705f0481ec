"""The products a practitioner calibrates: lens families, boards and IMU grades drawn per episode (``sensor.products``).

A ``SensorSampling`` describes one product: its datasheet (the distributions' means) and the spread of its units
around it. ``Products`` adds the level above: each episode first draws a product (which lens model and nominal
field of view, which printed board, which IMU grade), then a unit of it. The calibrator and the information state
are given what a user knows, the product's datasheet and the printed board, never the unit's values
(``vical.sim.sampling.draw_product``). Without ``products`` (``sensor=paper``) every episode is the same product.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from vical.config_checks import ConfigError, from_mapping, require, require_range
from vical.data.imu_grade import GRADES, ImuGrade
from vical.sim.settings import BoardConfig


@dataclass(frozen=True)
class Range:
    """A scalar drawn uniformly from ``[low, high]``; ``log: true`` draws its logarithm uniformly (a quantity that
    spans decades, as an IMU's noise across grades). Units of the quantity it describes."""

    low: float
    high: float
    log: bool = False

    def check(self, key: str) -> None:
        """Raise ``ConfigError`` naming ``key`` unless low <= high are finite (and positive when ``log``)."""
        for name in ("low", "high"):
            require(bool(np.isfinite(getattr(self, name))), f"{key}.{name}", "a finite number", getattr(self, name))
        require(self.high >= self.low, f"{key}.high", f"a number >= {key}.low ({self.low}): the range is empty",
                self.high)  # fmt: skip
        if self.log:
            require(self.low > 0, f"{key}.low", "a number > 0 (log: true draws the logarithm)", self.low)

    def draw(self, rng: np.random.Generator) -> float:
        if self.log:
            return float(np.exp(rng.uniform(np.log(self.low), np.log(self.high))))
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class LensChoice:
    """A lens family: its camera model (one of ``vical.sim.sampling.SAMPLED_MODELS``) and its nominal horizontal field
    of view [rad], drawn per episode; the unit's coefficients and FOV spread are ``sensor.camera``'s."""

    distortion: str
    hfov: Range
    weight: float = 1.0


@dataclass(frozen=True)
class BoardChoice:
    """A printed board (``vical.sim.settings.BoardConfig``'s geometry): ``kind``, ``rows`` x ``cols`` (checkerboard:
    inner corners; aprilgrid: tags), its square or tag size [m] drawn per episode, ``tag_spacing`` (aprilgrid) and
    ``border_squares`` (checkerboard). Where it stands is the workspace's (``sim.board.distance`` ...)."""

    kind: str
    rows: int
    cols: int
    square: Range
    tag_spacing: float = 0.3
    border_squares: float = 1.0
    weight: float = 1.0

    def geometry(self, square: float) -> dict[str, Any]:
        """The ``sim.board`` keys this board sets, at square (tag) size ``square`` [m]."""
        return {"kind": self.kind, "rows": self.rows, "cols": self.cols, "square": square,
                "tag_spacing": self.tag_spacing, "border_squares": self.border_squares}  # fmt: skip

    def check(self, key: str) -> None:
        """Build the board at both ends of its size range: a bad value is named by its key here."""
        self.square.check(f"{key}.square")
        for square in (self.square.low, self.square.high):
            try:
                BoardConfig(**self.geometry(square))
            except ConfigError as err:
                raise ConfigError(str(err).replace("sim.board", key)) from None


@dataclass(frozen=True)
class GradeChoice:
    """An IMU grade a product's IMU is made to (``vical.data.imu_grade.GRADES``: its scale and misalignment 1-sigma,
    from which each unit's terms are drawn and which its datasheet declares)."""

    grade: str
    weight: float = 1.0


@dataclass(frozen=True)
class Products:
    """What varies from one episode's product to the next (each empty / null: the ``sensor`` group's own).

    Attributes:
        lenses: lens families, one drawn per episode with probability proportional to its weight.
        boards: printed boards, one drawn per episode likewise.
        imu_noise_scale: the factor on all four of ``sensor.imu``'s noise densities (the IMU's noise grade); the
            datasheet states the scaled values.
        imu_grades: the IMU's scale and misalignment grades, one drawn per episode likewise (empty: the
            ``sensor.imu``'s own ``*_scale_std`` and ``*_misalignment_std``).
    """

    lenses: tuple[LensChoice, ...] = ()
    boards: tuple[BoardChoice, ...] = ()
    imu_noise_scale: Range | None = None
    imu_grades: tuple[GradeChoice, ...] = ()

    def __post_init__(self) -> None:
        key = "sensor.products"
        object.__setattr__(self, "lenses", _choices(self.lenses, LensChoice, f"{key}.lenses"))
        object.__setattr__(self, "boards", _choices(self.boards, BoardChoice, f"{key}.boards"))
        object.__setattr__(self, "imu_grades", _choices(self.imu_grades, GradeChoice, f"{key}.imu_grades"))
        for index, choice in enumerate(self.imu_grades):
            require(choice.grade in GRADES, f"{key}.imu_grades[{index}].grade", f"one of {list(GRADES)}",
                    choice.grade)  # fmt: skip
        for index, lens in enumerate(self.lenses):
            lens.hfov.check(f"{key}.lenses[{index}].hfov")
        for index, board in enumerate(self.boards):
            board.check(f"{key}.boards[{index}]")  # BoardConfig's own checks (kind, sizes), named by this key
        if self.imu_noise_scale is not None:
            self.imu_noise_scale.check(f"{key}.imu_noise_scale")
            require(self.imu_noise_scale.low > 0, f"{key}.imu_noise_scale.low", "a factor > 0",
                    self.imu_noise_scale.low)  # fmt: skip

    def pick_lens(self, rng: np.random.Generator) -> tuple[str, float] | None:
        """The episode's lens model and nominal hfov [rad], or None (the ``sensor.camera``'s)."""
        if not self.lenses:
            return None
        lens = _pick(self.lenses, rng)
        return lens.distortion, lens.hfov.draw(rng)

    def pick_board(self, rng: np.random.Generator) -> dict[str, Any] | None:
        """The episode's printed board (``sim.board`` keys), or None (the workspace's)."""
        if not self.boards:
            return None
        board = _pick(self.boards, rng)
        return board.geometry(board.square.draw(rng))

    def imu_scale(self, rng: np.random.Generator) -> float:
        """The episode's factor on the IMU's noise (1 without ``imu_noise_scale``)."""
        return 1.0 if self.imu_noise_scale is None else self.imu_noise_scale.draw(rng)

    def pick_grade(self, rng: np.random.Generator) -> ImuGrade | None:
        """The episode's IMU scale and misalignment grade, or None (the ``sensor.imu``'s)."""
        return GRADES[_pick(self.imu_grades, rng).grade] if self.imu_grades else None


def _choices(items: Any, cls: type, key: str) -> tuple[Any, ...]:
    """A list of mappings (or of ``cls``) as a tuple of ``cls``; weights >= 0 and not all 0."""
    require(isinstance(items, Sequence) and not isinstance(items, str), key, "a list ([] for none)", items)
    built = []
    for index, item in enumerate(items):
        where = f"{key}[{index}]"
        if not isinstance(item, cls):
            require(isinstance(item, Mapping), where, f"a mapping of {cls.__name__}'s settings", item)
            item = from_mapping(cls, item, where)
        require_range(f"{where}.weight", item.weight, 0.0)
        built.append(item)
    if built:
        require(sum(item.weight for item in built) > 0, f"{key}[].weight", "at least one weight above 0",
                [item.weight for item in built])  # fmt: skip
    return tuple(built)


def _pick(items: tuple[Any, ...], rng: np.random.Generator) -> Any:
    weights = np.array([item.weight for item in items], dtype=float)
    return items[int(rng.choice(len(items), p=weights / weights.sum()))]


def replace_board(board: BoardConfig, geometry: Mapping[str, Any] | None) -> BoardConfig:
    """``board`` printed as ``geometry`` (``Products.pick_board``), standing where it stands; None: ``board``."""
    return board if geometry is None else replace(board, **geometry)
