"""Where the camera may go: workspace offsets <-> world poses, and what the Panda reaches of them.

A workspace offset ``[x, y, z [m], roll, pitch, yaw [rad]]`` (``vical.env.settings.Workspace``)
becomes the camera body pose (the ``ee`` site: x along the optical axis, y left, z up) as

    p = p_start + [x, y, z],    R = R_ref(p) Rz(yaw0 + yaw) Ry(pitch0 + pitch) Rx(roll0 + roll)

where ``R_ref`` is the identity for ``frame=start`` (world Euler angles, the authors' workspace)
and, for ``frame=board``, the upright orientation looking from ``p`` at the board centre (its
x toward the centre, its y horizontal); ``[roll0, pitch0, yaw0]`` are the start pose's angles in
that reference, so the zero offset is the start pose. With ``frame=board`` the zero orientation
offset keeps the board centred wherever the camera goes; yaw and pitch move the board across
the image and roll turns it about the optical axis.

The world is the simulator's: z up, the start pose looking along +x at the board. A robot's base may stand
turned about its vertical axis against the board; ``PoseFrame``'s ``heading`` (the horizontal direction from
the start toward the board, in the base's coordinates) turns the offsets into that world, so that a +x offset
still goes toward the board and the angles' reference is the same (``p = p_start + H [x, y, z]``, ``R_ref = H``
for ``frame=start``, with ``H`` the turn about z that takes +x to the heading).

A pose is *reachable* when the damped-least-squares IK finds joint positions within the joint
ranges (less the planning margin) and MuJoCo reports no contact there: neither between the arm's
links nor with the board, its stand or the floor.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from vical.config_checks import ConfigError
from vical.data import Target
from vical.env.settings import Workspace
from vical.geometry import CameraModel, euler_to_matrix, make_transform, matrix_to_euler
from vical.sim import PandaSim
from vical.sim.camera import ProjectBackend

AXES = ("x", "y", "z", "roll", "pitch", "yaw")
UNITS = ("m", "m", "m", "rad", "rad", "rad")
_UP = np.array([0.0, 0.0, 1.0])
# Bisection steps that locate the reachable end of an axis (2^-10 of its bound: 0.5 mm on 0.5 m).
_BISECTIONS = 10


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi)."""
    return (np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def look_at_rotation(position: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(3, 3) camera-body orientation at ``position`` (3,) [m] looking at ``point`` (3,) [m], upright; a stack of
    positions (..., 3) gives (..., 3, 3).

    Body x points at ``point``, body y is horizontal (to the left of the line of sight), body z up.
    Undefined when the line of sight is vertical.
    """
    x = np.asarray(point, dtype=float) - np.asarray(position, dtype=float)
    x = x / _norms(x)
    y = np.cross(_UP, x)
    norm = _norms(y)
    if np.any(norm < 1e-9):
        raise ValueError("look_at_rotation: the line of sight is vertical, the upright orientation is undefined")
    y = y / norm
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _norms(v: np.ndarray) -> np.ndarray:
    """The Euclidean norms of ``v``'s vectors along its last axis, that axis kept. One vector's is numpy's dot product
    and a stack's a sum, which round differently (by 1e-16): the one-vector path keeps the simulated arm's goals, and
    so every seeded episode, bit for bit as they have been."""
    return np.linalg.norm(v) if v.ndim == 1 else np.linalg.norm(v, axis=-1, keepdims=True)


class PoseFrame:
    """Maps workspace offsets to camera body poses in the world and back (module doc).

    Args:
        T_start: (4, 4) camera body pose at the episode start (``T_world_ee``; a robot's ``T_base_tool``).
        frame: ``start`` or ``board``.
        look_at: (3,) [m] the board centre in the poses' coordinates (read for ``frame=board``).
        heading: (3,) the direction the workspace's +x points along in the poses' coordinates, made horizontal
            (a robot's: from the start toward the board); None: their own +x (the simulator's world).
    """

    def __init__(self, T_start: np.ndarray, frame: str, look_at: np.ndarray, heading: np.ndarray | None = None) -> None:
        if frame not in ("start", "board"):
            raise ValueError(f"frame must be 'start' or 'board', got {frame!r}")
        self.frame = frame
        self.look_at = np.asarray(look_at, dtype=float)
        self.axes = None if heading is None else heading_axes(heading)
        self.p_start = np.asarray(T_start, dtype=float)[:3, 3].copy()
        self.euler_start = matrix_to_euler(self.reference(self.p_start).T @ T_start[:3, :3])

    def reference(self, position: np.ndarray) -> np.ndarray:
        """(3, 3) the orientation that zero angle offsets mean at ``position`` (3,) [m] (a stack (..., 3): (..., 3, 3)
        for ``frame=board``, the one (3, 3) for ``frame=start``)."""
        if self.frame == "board":
            return look_at_rotation(position, self.look_at)
        return np.eye(3) if self.axes is None else self.axes

    def pose(self, offset: np.ndarray) -> np.ndarray:
        """(4, 4) ``T_world_ee`` of the workspace ``offset`` (6,); a stack of offsets (..., 6) gives (..., 4, 4) in one
        vectorised pass (the planner's predictions map hundreds of offsets a step)."""
        offset = np.asarray(offset, dtype=float)
        step = offset[..., :3] if self.axes is None else offset[..., :3] @ self.axes.T
        p = self.p_start + step
        return make_transform(self.reference(p) @ euler_to_matrix(self.euler_start + offset[..., 3:]), p)

    def offset(self, T_world_ee: np.ndarray) -> np.ndarray:
        """(6,) the workspace offset of the pose ``T_world_ee`` (4, 4) (inverse of ``pose``)."""
        p = T_world_ee[:3, 3]
        euler = matrix_to_euler(self.reference(p).T @ T_world_ee[:3, :3])
        step = p - self.p_start
        return np.r_[step if self.axes is None else self.axes.T @ step, wrap_angle(euler - self.euler_start)]


def heading_axes(heading: np.ndarray) -> np.ndarray:
    """(3, 3) the workspace's axes in a turned base's coordinates: x along ``heading`` (3,) made horizontal, z up."""
    x = np.asarray(heading, dtype=float) * [1.0, 1.0, 0.0]
    norm = np.linalg.norm(x)
    if norm < 1e-9:
        raise ValueError("heading: the direction toward the board is vertical, the workspace's x is undefined")
    x /= norm
    return np.c_[x, np.cross(_UP, x), _UP]


def board_centre(sim: PandaSim) -> np.ndarray:
    """(3,) [m] the board centre in the world."""
    T = sim.T_world_board
    return T[:3, :3] @ sim.cfg.board.target.center + T[:3, 3]


def pose_frame(sim: PandaSim, workspace: Workspace) -> PoseFrame:
    """The pose frame of ``workspace`` around the simulator's start pose."""
    sim.reset()
    return PoseFrame(sim.ee_pose(), workspace.frame, board_centre(sim))


def unreachable_reason(sim: PandaSim, T_world_ee: np.ndarray) -> str:
    """Why the Panda cannot hold the camera body at ``T_world_ee`` (4, 4) ('' when it can; module doc)."""
    ik = sim.ik.solve(T_world_ee, sim.q_start, np.random.default_rng(0))
    if not ik.success:
        return f"beyond reach ({1e3 * ik.position_error:.0f} mm / {np.degrees(ik.rotation_error):.1f} deg short)"
    touching = sim.contact_at(ik.q)
    return f"contact: {touching}" if touching else ""


def _axis_offset(axis: int, value: float) -> np.ndarray:
    offset = np.zeros(6)
    offset[axis] = value
    return offset


def reachable_extent(sim: PandaSim, frame: PoseFrame, axis: int, end: float) -> float:
    """How far along ``axis`` toward ``end`` (the other offsets zero) the poses stay reachable.

    Bisects between the start pose (reachable) and ``end``; returns ``end`` when it is reachable.
    """
    if not unreachable_reason(sim, frame.pose(_axis_offset(axis, end))):
        return end
    good, bad = 0.0, end
    for _ in range(_BISECTIONS):
        middle = 0.5 * (good + bad)
        if unreachable_reason(sim, frame.pose(_axis_offset(axis, middle))):
            bad = middle
        else:
            good = middle
    return good


def check_workspace(sim: PandaSim, frame: PoseFrame, workspace: Workspace) -> None:
    """Refuse a workspace whose bound on some axis the arm cannot reach (one line naming key, why and range).

    Every axis end (one offset at its bound, the others zero) must be reachable: within the arm's
    reach and free of contact with itself, the board, its stand and the floor. Corners of the box
    may not be (``reachable_fraction`` measures how much of it is).
    """
    for axis, bound in enumerate(workspace.bound):
        reasons = {end: unreachable_reason(sim, frame.pose(_axis_offset(axis, end))) for end in (bound, -bound)}
        failed = [f"{end:+g} {UNITS[axis]} ({why})" for end, why in reasons.items() if why]
        if not failed:
            continue
        low = reachable_extent(sim, frame, axis, -bound)
        high = reachable_extent(sim, frame, axis, bound)
        key = "env.workspace." + ("position" if axis < 3 else "orientation")
        raise ConfigError(
            f"{key} ({AXES[axis]}) = {bound:g} {UNITS[axis]}: from the start pose the arm cannot reach "
            f"{' nor '.join(failed)}; reachable along {AXES[axis]}: [{low:+.3f}, {high:+.3f}] {UNITS[axis]}; "
            "reduce the bound or move the start pose (sim.start) and the board"
        )


@dataclass(frozen=True)
class Reachability:
    """How much of a workspace box the arm reaches, from uniform samples.

    Attributes:
        samples: poses tried.
        reachable: fraction reachable.
        reasons: counts of the failure kinds (``beyond reach``, ``contact: <geoms>``).
    """

    samples: int
    reachable: float
    reasons: dict[str, int]


def reachable_fraction(sim: PandaSim, frame: PoseFrame, bound: np.ndarray, samples: int, seed: int = 0) -> Reachability:
    """Fraction of ``samples`` offsets drawn uniformly in ``[-bound, bound]`` (6,) that are reachable."""
    rng = np.random.default_rng(seed)
    reasons: Counter[str] = Counter()
    for offset in rng.uniform(-bound, bound, size=(samples, 6)):
        reason = unreachable_reason(sim, frame.pose(offset))
        if reason:
            reasons["beyond reach" if reason.startswith("beyond") else reason] += 1
    return Reachability(samples, 1.0 - sum(reasons.values()) / samples, dict(reasons))


# Fronto-parallel distances tried across the workspace's reach along the line of sight, and the share of the
# board's corners one of them must show for a product's board to count as usable with its camera.
_SIGHT_DISTANCES = 5
USABLE_SHARE = 0.25


def board_in_sight(target: Target, camera: CameraModel, near: float, far: float) -> bool:
    """Whether ``camera`` sees at least ``USABLE_SHARE`` of ``target``'s corners, under the analytic backend's
    detector rules, from some distance in ``[near, far]`` [m] facing the board centre: a practitioner does not
    calibrate with a board their camera cannot detect from where they can hold it (tags too small for a wide lens,
    a checkerboard that never fits the image)."""
    backend = ProjectBackend(target, np.eye(4), 0.0)
    R_board_cam = np.diag([1.0, -1.0, -1.0])  # looking along -z of the board, its z toward the camera
    for distance in np.linspace(near, far, _SIGHT_DISTANCES):
        T_board_cam = make_transform(R_board_cam, target.center + [0.0, 0.0, distance])
        _, ids = backend.ideal_observation(camera, T_board_cam)
        if len(ids) >= USABLE_SHARE * target.num_points:
            return True
    return False


def sight_range(distance: float, workspace: Workspace) -> tuple[float, float]:
    """The nearest and farthest camera-board distances [m] along the line of sight: the board ``distance`` ahead of
    the start pose, less and plus the workspace's bound along world x (the start pose looks along it)."""
    return max(distance - workspace.position[0], 0.05), distance + workspace.position[0]
