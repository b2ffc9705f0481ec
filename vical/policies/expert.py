"""Expert baselines: how an experienced calibration engineer moves a camera + IMU in front of a board.

Written for a workspace whose orientation offsets are relative to the line of sight to the board
(``frame=board``, ``conf/workspace/practitioner.yaml``), after Kalibr's recommended routine:

1. **Views for the camera** (intrinsics): the board close, at mid range and far; seen head-on and
   tilted both ways about each of its in-plane axes (the camera moved to the left, right, above
   and below the board while looking at it); placed in every image corner and along the edges
   (the camera turned away from the line of sight); rolled both ways about the optical axis.
2. **Excitation for the IMU** (extrinsic, time offset): swings back and forth along each
   translation axis and about each rotation axis, the board kept in view.

The ``intrinsic`` trajectory is part 1, ``extrinsic`` part 2 (from the start pose), ``joint`` both
in one recording. The ``long`` version is what an expert records when time does not matter; the
``short`` one keeps one view per idea and a single swing per axis (about a third of the path).

Waypoints are written in fractions of the workspace bound and scaled to the env's workspace at
every reset, so every waypoint lies inside it. ``view`` names what a waypoint does to the image.
"""

from __future__ import annotations

import numpy as np

from vical.env.calibration import CalibrationEnv
from vical.policies.base import WaypointPolicy, require_frame

TASKS = ("intrinsic", "extrinsic", "joint")
LENGTHS = ("long", "short")
# Distances as fractions of the workspace's x bound (toward the board). The far end of the practitioner's
# box is at the edge of the Panda's reach: an arm that got there through other views may miss it by a few
# cm, so the expert stays a little inside it (SIDE: also for turning there and for views from the side near
# the board), as an expert who knows the arm would.
NEAR, MIDDLE, FAR = 1.0, 0.0, -0.8
SIDE = 0.8
# Board-centre placements in the image as (right, down) in [-1, 1]: the four corners, then the
# midpoints of the four edges.
CORNERS = ((-1, -1), (1, -1), (1, 1), (-1, 1))
EDGES = ((0, -1), (1, 0), (0, 1), (-1, 0))
# Where the camera stands beside the board to see it tilted: (left, up) in [-1, 1]. The Panda cannot
# hold the camera above the board when near it, nor below it when far (docs/workspace.md), so those
# views are taken at mid range only, as an expert who knows the arm would.
SIDES = ((1, 0), (-1, 0), (0, 1), (0, -1))
SIDES_AT = {NEAR: ((1, 0), (-1, 0), (0, -1)), MIDDLE: SIDES, FAR: ((1, 0), (-1, 0), (0, 1))}


def view(
    closer: float = 0.0,
    left: float = 0.0,
    up: float = 0.0,
    roll: float = 0.0,
    right: float = 0.0,
    down: float = 0.0,
) -> np.ndarray:
    """(6,) workspace offset ``[x, y, z, roll, pitch, yaw]`` in fractions of the bound (frame=board).

    Args:
        closer: toward the board (+1: nearest) or away (-1: farthest).
        left, up: stand to the left of / above the board (the board is seen tilted; the line of
            sight still meets its centre).
        roll: turn about the optical axis (+1: the whole roll bound).
        right, down: turn the camera so that the board centre moves toward the image's right /
            bottom edge.
    """
    return np.clip(np.array([closer, left, up, roll, -down, right], dtype=float), -1.0, 1.0)


def image_sweep(
    distance: float, placements: tuple[tuple[int, int], ...], roll: float, reach: float = 1.0
) -> list[np.ndarray]:
    """The board centre toward each ``placement`` (right, down) at ``distance``, the roll alternating +-``roll``.

    ``reach`` scales how far toward the image's corners and edges the camera turns (1: the whole bound).
    """
    return [
        view(closer=distance, right=reach * r, down=reach * d, roll=roll * (-1) ** i)
        for i, (r, d) in enumerate(placements)
    ]


def tilted_views(distance: float, amount: float = 1.0) -> list[np.ndarray]:
    """The board centred and seen from the left, right, above and below (tilted both ways about both axes).

    ``distance`` is NEAR, MIDDLE or FAR; the sides the arm reaches there (``SIDES_AT``) are used.
    """
    return [view(closer=distance, left=amount * left, up=amount * up) for left, up in SIDES_AT[distance]]


def roll_views(distance: float, amount: float = 1.0) -> list[np.ndarray]:
    """The board centred, rolled both ways about the optical axis."""
    return [view(closer=distance, roll=amount), view(closer=distance, roll=-amount)]


def camera_views(length: str) -> list[np.ndarray]:
    """Part 1: the views a camera calibration needs."""
    if length == "short":
        return [
            *image_sweep(NEAR, CORNERS, roll=0.5),
            *tilted_views(MIDDLE),
            *roll_views(MIDDLE),
            view(closer=FAR),
        ]
    return [
        *image_sweep(NEAR, CORNERS + EDGES, roll=0.25),
        *tilted_views(NEAR),
        *roll_views(NEAR),
        # Seen from the side and off-centre at once: the strongest perspective, near the image corners.
        *[view(closer=NEAR, left=-SIDE * r, right=r, down=d) for r, d in CORNERS],
        *image_sweep(MIDDLE, CORNERS, roll=0.25),
        *tilted_views(MIDDLE),
        *roll_views(MIDDLE),
        *image_sweep(FAR, CORNERS, roll=0.25, reach=SIDE),
        *tilted_views(FAR),
    ]


# Swing amplitudes per axis [x, y, z, roll, pitch, yaw] (fractions of the bound): +-45 deg of roll
# excites the gyro as well as +-90 deg and takes half the time; along x the far end stays inside reach.
SWING = np.array([-FAR, 1.0, 1.0, 0.5, 1.0, 1.0])


def excitation(length: str) -> list[np.ndarray]:
    """Part 2: back-and-forth swings along / about each of the six axes in turn, back to the start pose."""
    scale, cycles = (0.6, 1) if length == "short" else (1.0, 2)
    moves = []
    for axis in range(6):
        unit = np.zeros(6)
        unit[axis] = scale * SWING[axis]
        moves += [sign * unit for _ in range(cycles) for sign in (1.0, -1.0)]
        moves.append(np.zeros(6))
    return moves


def expert_fractions(task: str, length: str) -> np.ndarray:
    """(K, 6) waypoints of an expert trajectory in fractions of the workspace bound."""
    if task not in TASKS:
        raise ValueError(f"expert trajectories exist for tasks {TASKS}, got task={task!r}")
    if length not in LENGTHS:
        raise ValueError(f"expert trajectories come in lengths {LENGTHS}, got length={length!r}")
    parts = {"intrinsic": camera_views(length), "extrinsic": excitation(length)}
    parts["joint"] = parts["intrinsic"] + [view()] + parts["extrinsic"]
    return np.array(parts[task])


class ExpertPolicy(WaypointPolicy):
    """An expert trajectory, scaled to the workspace of the env it runs in (at ``reset``).

    Args:
        task: ``intrinsic``, ``extrinsic`` or ``joint``: which calibration it collects data for.
        length: ``long`` or ``short``.
        name: shown in evaluation tables.
    """

    def __init__(self, task: str, length: str, name: str | None = None) -> None:
        self.fractions = expert_fractions(task, length)
        super().__init__(self.fractions, name or f"expert ({length})")
        self.task, self.length = task, length
        self.max_steps = self.STEPS_PER_WAYPOINT * len(self.fractions)  # big rolls take a few steps

    def check(self, env: CalibrationEnv) -> None:
        require_frame(
            env, "board", "the expert trajectories (workspace=practitioner)", "use the hand-crafted trajectories there"
        )

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self.waypoints = self.fractions * env.config.workspace.bound
        super().reset(env, rng)


def expert_policy(task: str, length: str, name: str | None = None) -> ExpertPolicy:
    """The expert trajectory for ``task`` of ``length`` (the factory ``conf/policy/expert_*.yaml`` names)."""
    return ExpertPolicy(task, length, name)
