"""What to tell a person who holds the sensor: the motion from where it is to where it should go, in words.

``vical-guide`` shows a person the next pose as the board's outline in the live image and as a short instruction
("move 20 cm closer, tilt the top away 25 deg"). The words describe the motion in the sensor's own axes, as the
person holding it behind the camera sees them: the camera's optical frame (x right, y down in the image, z forward
along the optical axis, ``docs/conventions.md``). From the current camera pose to the suggested one (both
``T_board_cam``):

- **translation** (in the current camera's axes): along z "closer" / "farther back", along x "right" / "left",
  along y "down" / "up";
- **rotation** (its rotation vector in the current camera's axes): about z (the optical axis, pointing away from
  the person) "roll clockwise" / "roll counter-clockwise" (a positive turn about an axis pointing away is
  clockwise to the one who looks along it); about x "tilt the top toward you" (positive: the optical axis turns up,
  toward -y) / "tilt the top away"; about y "turn right" (positive: the optical axis turns toward +x) / "turn left".

Only parts at least ``min_move`` [m] or ``min_turn`` [deg] large are said, the largest first (translations by their
length, rotations by their angle; a metre weighs as ``METRE_AS_DEGREES``), at most ``max_parts`` of them; a
suggestion closer than both thresholds reads "hold still". Lengths are rounded to 5 cm and angles to 5 deg: a
person cannot place a hand-held sensor more finely (the simulated person's placement error is 7 cm and 10 deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vical.config_checks import require_range

METRE_AS_DEGREES = 100.0  # the weight of a metre of translation against a degree of rotation when ordering parts
HOLD_STILL = "hold still"
# (positive, negative) words per camera axis x, y, z
MOVES = (("right", "left"), ("down", "up"), ("closer", "farther back"))
TURNS = (("tilt the top toward you", "tilt the top away"), ("turn right", "turn left"),
         ("roll clockwise", "roll counter-clockwise"))  # fmt: skip


@dataclass(frozen=True)
class Wording:
    """How much is worth saying (module doc).

    Attributes:
        min_move: [m] the shortest translation along an axis that is said.
        min_turn: [deg] the smallest rotation about an axis that is said.
        max_parts: the most parts one instruction has.
    """

    min_move: float = 0.05
    min_turn: float = 10.0
    max_parts: int = 2

    def __post_init__(self) -> None:
        require_range("guide.wording.min_move", self.min_move, 0.0, low_open=True)
        require_range("guide.wording.min_turn", self.min_turn, 0.0, low_open=True)
        require_range("guide.wording.max_parts", self.max_parts, 1)


def instruction(T_board_cam: np.ndarray, T_board_goal: np.ndarray, wording: Wording | None = None) -> str:
    """The instruction that takes the camera from ``T_board_cam`` (4, 4) to ``T_board_goal`` (4, 4) (module doc)."""
    w = wording or Wording()
    R = np.asarray(T_board_cam, dtype=float)[:3, :3]
    move = R.T @ (np.asarray(T_board_goal, dtype=float)[:3, 3] - np.asarray(T_board_cam, dtype=float)[:3, 3])
    turn = np.degrees(Rotation.from_matrix(R.T @ np.asarray(T_board_goal, dtype=float)[:3, :3]).as_rotvec())
    parts = []  # (weight, words)
    for axis in range(3):
        if abs(move[axis]) >= w.min_move:
            words = MOVES[axis][0 if move[axis] > 0 else 1]
            parts.append((abs(move[axis]) * METRE_AS_DEGREES, f"move {_rounded(100 * abs(move[axis]))} cm {words}"))
        if abs(turn[axis]) >= w.min_turn:
            words = TURNS[axis][0 if turn[axis] > 0 else 1]
            parts.append((abs(turn[axis]), f"{words} {_rounded(abs(turn[axis]))} deg"))
    if not parts:
        return HOLD_STILL
    parts.sort(key=lambda part: -part[0])
    return ", ".join(words for _, words in parts[: w.max_parts])


def _rounded(value: float) -> int:
    """``value`` to the nearest multiple of 5, at least 5."""
    return max(5, 5 * round(value / 5))
