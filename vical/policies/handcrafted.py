"""Hand-crafted calibration trajectories: how an expert moves a sensor in front of a board.

Each trajectory is a list of waypoints (pose offsets from the episode's start pose, reached by
``WaypointPolicy``) composed from named *view moves*: what a waypoint does to the camera's view of
the board. Moves are written in fractions of the env's workspace bound (``conf/env/calibration.yaml``:
+-[0.08, 0.10, 0.08] m, +-[0.17, 0.15, 0.12] rad), so every waypoint lies inside the workspace and
the trajectories scale with it.

The start pose faces the board along world +x at 1.5 m. Measured in the simulator (one bound each):
+y (camera left) and +yaw (pan left) move the board to the right of the image (u/W 0.50 -> 0.56 and
0.62); +z (camera up) and -pitch move it down (v/H 0.50 -> 0.57 and 0.69); +x brings it closer
(area x1.1); roll turns it about the optical axis.

- intrinsic: sweep the board centre over the image's four quadrants and edges, tilt the camera both
  ways about each axis, at several distances (the views a camera calibration needs);
- extrinsic: swing the sensor back and forth about every rotation axis and along every translation
  axis (the excitation a camera-IMU calibration needs), the board kept in view.

The ``long`` versions have 3-4x the path of the ``short`` ones (``docs/evaluation.md``).
"""

from __future__ import annotations

import numpy as np

from vical.env.calibration import CalibrationEnv
from vical.env.settings import Workspace
from vical.policies.base import WaypointPolicy, require_frame

TASKS = ("intrinsic", "extrinsic")
LENGTHS = ("long", "short")

# Board-centre targets in the image as (right, down) in [-1, 1]: the border clockwise from the
# top-left corner (corners and edge midpoints), and the four quadrants.
IMAGE_BORDER = ((-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0))
QUADRANTS = ((-1, -1), (1, -1), (1, 1), (-1, 1))
DIAGONALS = ((-1, -1), (1, 1), (1, -1), (-1, 1))
NEAR, MIDDLE, FAR = 1.0, 0.0, -1.0


def view(
    right: float = 0.0, down: float = 0.0, closer: float = 0.0, roll: float = 0.0, pan: float = 0.0, nod: float = 0.0
) -> np.ndarray:
    """(6,) pose offset ``[x, y, z, roll, pitch, yaw]`` in workspace fractions, clipped to [-1, 1].

    Args:
        right, down: move the board centre toward the image's right / bottom edge: the camera
            translates and rotates together, which shifts the image most within the workspace.
        closer: move toward the board (+) or away from it (-).
        roll: rotate about the optical axis.
        pan: rotate about the vertical axis (+: left), the board seen obliquely from the side.
        nod: rotate about the horizontal axis (+: down), the board seen obliquely from above/below.
    """
    offset = np.array([closer, right, down, roll, nod - down, right + pan], dtype=float)
    return np.clip(offset, -1.0, 1.0)


def sweep(
    targets: tuple[tuple[int, int], ...], closer: float, roll: float = 0.0, depth: float = 0.0
) -> list[np.ndarray]:
    """The board centre visits ``targets`` (right, down) at distance ``closer`` +- ``depth``.

    Consecutive targets alternate the roll (+-``roll``) and the distance (+-``depth``), so the views
    also differ in in-plane rotation and board size.
    """
    return [
        view(right=r, down=d, closer=closer + depth * (-1) ** i, roll=roll * (-1) ** i)
        for i, (r, d) in enumerate(targets)
    ]


def tilts(closer: float, amplitude: float = 1.0) -> list[np.ndarray]:
    """The board centred, the camera tilted both ways about each axis (roll, pan, nod) at one distance."""
    moves = []
    for axis in ("roll", "pan", "nod"):
        moves += [view(closer=closer, **{axis: amplitude}), view(closer=closer, **{axis: -amplitude})]
    return moves


def axis_swings(amplitude: float, cycles: int) -> list[np.ndarray]:
    """Back-and-forth swings along / about each of the 6 axes in turn, ``cycles`` times, back to the start."""
    moves = []
    for axis in range(6):
        unit = np.zeros(6)
        unit[axis] = amplitude
        moves += [sign * unit for _ in range(cycles) for sign in (1.0, -1.0)]
        moves.append(np.zeros(6))
    return moves


def intrinsic_moves(length: str) -> list[np.ndarray]:
    """The intrinsic trajectory as view moves (workspace fractions)."""
    if length == "short":
        # Four quadrants, near and far, rolled both ways; then one tilt each way per axis.
        return [*sweep(QUADRANTS, MIDDLE, roll=1.0, depth=1.0), *tilts(MIDDLE), view()]
    moves = []
    for distance in (NEAR, MIDDLE, FAR):
        moves += [*sweep(IMAGE_BORDER, distance, roll=1.0), *tilts(distance)]
    return [*moves, *sweep(DIAGONALS, MIDDLE, roll=0.5), view()]


def extrinsic_moves(length: str) -> list[np.ndarray]:
    """The extrinsic trajectory as view moves: one axis at a time, back and forth."""
    if length == "short":
        return axis_swings(amplitude=0.6, cycles=1)
    return axis_swings(amplitude=1.0, cycles=2)


def handcrafted_fractions(task: str, length: str) -> np.ndarray:
    """(K, 6) waypoints of a hand-crafted trajectory in fractions of the workspace bound."""
    if task not in TASKS:
        raise ValueError(f"hand-crafted trajectories exist for tasks {TASKS}, got task={task!r}")
    if length not in LENGTHS:
        raise ValueError(f"hand-crafted trajectories come in lengths {LENGTHS}, got length={length!r}")
    moves = intrinsic_moves(length) if task == "intrinsic" else extrinsic_moves(length)
    return np.array(moves)


def handcrafted_waypoints(task: str, length: str, workspace: Workspace) -> np.ndarray:
    """(K, 6) waypoints ``[x, y, z [m], roll, pitch, yaw [rad]]`` inside ``workspace``."""
    return handcrafted_fractions(task, length) * workspace.bound


class HandcraftedPolicy(WaypointPolicy):
    """A hand-crafted trajectory, scaled to the workspace of the env it runs in (at ``reset``).

    Args:
        task: ``intrinsic`` or ``extrinsic``: which calibration the trajectory is made for.
        length: ``long`` or ``short``.
        name: shown in evaluation tables.
    """

    def __init__(self, task: str, length: str, name: str | None = None) -> None:
        super().__init__(
            handcrafted_waypoints(task, length, Workspace()), name or f"hand-crafted trajectory ({length})"
        )
        self.task, self.length = task, length
        # Every waypoint takes one step (actions reach across the workspace); the margin covers
        # waypoints the arm approaches in two steps.
        self.max_steps = 2 * len(self.waypoints)

    def check(self, env: CalibrationEnv) -> None:
        require_frame(
            env, "start", "the hand-crafted trajectories (the authors' box, workspace=paper)", "use the expert ones"
        )

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self.waypoints = handcrafted_waypoints(self.task, self.length, env.config.workspace)
        super().reset(env, rng)


def handcrafted_policy(task: str, length: str, name: str | None = None) -> HandcraftedPolicy:
    """The hand-crafted trajectory for ``task`` of ``length`` (the factory ``conf/policy/handcrafted_*.yaml`` name)."""
    return HandcraftedPolicy(task, length, name)
