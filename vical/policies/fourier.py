"""Fourier-series trajectories: the "random trajectory" and "model-based learned trajectory" baselines.

Chen et al. 2020 move the sensor along a closed loop whose six pose offsets (x, y, z [m], roll,
pitch, yaw [rad], from the episode's start pose) are each a Fourier series with cosine and sine
terms of harmonics 1, 2 and 4 of one loop period: 6 x 2 x 3 = 36 coefficients. vical keeps that
parametrisation and fits the loop into the env's workspace without clipping:

* coefficients are in units of the workspace bound of their DoF (``MdpConfig.workspace``);
* per DoF, if the sum of the harmonics' amplitudes ``sum_h sqrt(a_h^2 + b_h^2)`` exceeds 1, that
  DoF's six coefficients are divided by the sum, so ``|offset| <= bound`` at every phase.

The loop is sampled at ``num_waypoints`` phases ``t = k / (num_waypoints - 1)``, ``k = 0..K-1``
(the last waypoint closes the loop on the first), and ``WaypointPolicy`` visits them one after
another: the arm stops at each waypoint, so the executed motion is the polygon through the samples,
not a continuous sweep. The arm starts at the start pose (offset 0) and first travels to the
loop's phase-0 point. See docs/baselines.md.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from vical.config_checks import ConfigError
from vical.env.calibration import CalibrationEnv
from vical.env.settings import Workspace
from vical.policies.base import WaypointPolicy

HARMONICS = (1, 2, 4)
SHAPE = (6, 2, len(HARMONICS))  # DoF x (cos, sin) x harmonic
NUM_COEFFICIENTS = int(np.prod(SHAPE))
DOF_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
TASKS = ("intrinsic", "extrinsic", "joint")
DEFAULT_WAYPOINTS = 21  # 20 segments: the paper's 20-step episodes; >= 8 samples per period of harmonic 4
# Package data, not a conf/policy option: the fit's artefact that the model_based policy reads.
DEFAULT_PARAMS_FILE = Path(__file__).resolve().parent / "params" / "model_based.yaml"
FIT_COMMAND = "python experiments/fit_model_based_trajectory.py"


def workspace_bound(workspace: Workspace | None = None) -> np.ndarray:
    """(6,) +- bounds [m, m, m, rad, rad, rad] of the pose offset (the paper's workspace by default)."""
    return (workspace or Workspace()).bound


class FourierTrajectory:
    """A closed loop of pose offsets given by 36 Fourier coefficients.

    Args:
        coefficients: (6, 2, 3) or 36 numbers: ``[dof, (cos, sin), harmonic]`` for harmonics
            ``HARMONICS``, in units of the workspace bound of the DoF. DoFs whose amplitude sum
            exceeds 1 are scaled down to 1 (module doc), so any finite coefficients are valid.
    """

    def __init__(self, coefficients: np.ndarray | Sequence[Any]):
        c = np.asarray(coefficients, dtype=float)
        if c.size != NUM_COEFFICIENTS or c.shape not in {SHAPE, (NUM_COEFFICIENTS,)} or not np.all(np.isfinite(c)):
            raise ValueError(
                f"a Fourier trajectory needs {NUM_COEFFICIENTS} finite coefficients shaped {SHAPE} "
                f"(dof x (cos, sin) x harmonics {HARMONICS}), got shape {c.shape}"
            )
        self.raw = c.reshape(SHAPE)
        self.coefficients = self.raw / np.maximum(1.0, self.amplitude_sums(self.raw))[:, None, None]

    @staticmethod
    def amplitude_sums(coefficients: np.ndarray) -> np.ndarray:
        """(6,) per DoF, the sum over harmonics of ``sqrt(cos^2 + sin^2)`` (bound units)."""
        c = np.asarray(coefficients, dtype=float).reshape(SHAPE)
        return np.sqrt((c**2).sum(axis=1)).sum(axis=1)

    @classmethod
    def random(cls, rng: np.random.Generator) -> FourierTrajectory:
        """Coefficients uniform in [-1, 1] (the PSO's search box), then fitted into the workspace."""
        return cls(rng.uniform(-1.0, 1.0, SHAPE))

    def evaluate(self, phase: np.ndarray, bound: np.ndarray | None = None) -> np.ndarray:
        """(N, 6) pose offsets [m, rad] at ``phase`` (N,) in loop periods (1.0 = one whole loop).

        ``bound``: (6,) workspace bounds that scale the unit coefficients (default the paper's).
        """
        t = np.atleast_1d(np.asarray(phase, dtype=float))
        b = workspace_bound() if bound is None else np.asarray(bound, dtype=float)
        angle = 2 * np.pi * t[:, None] * np.asarray(HARMONICS, dtype=float)[None, :]  # (N, H)
        unit = np.cos(angle) @ self.coefficients[:, 0, :].T + np.sin(angle) @ self.coefficients[:, 1, :].T
        return unit * b[None, :]

    def offsets(self, num_waypoints: int = DEFAULT_WAYPOINTS, bound: np.ndarray | None = None) -> np.ndarray:
        """(K, 6) waypoints [m, rad] at phases ``k / (K - 1)``: uniform over the loop, the last closing it."""
        if not isinstance(num_waypoints, int | np.integer) or num_waypoints < 2:
            raise ValueError(f"num_waypoints must be an integer >= 2 (a loop's start and end), got {num_waypoints!r}")
        return self.evaluate(np.linspace(0.0, 1.0, int(num_waypoints)), bound)


class FourierTrajectoryPolicy(WaypointPolicy):
    """Visits ``num_waypoints`` samples of a Fourier loop, scaled to the env's workspace at each reset.

    Args:
        trajectory: the loop.
        num_waypoints: samples of the loop (the last equals the first).
        name: shown in evaluation tables.
        redraw: draw a new random loop from the episode's ``rng`` at every reset (random baseline).
    """

    def __init__(
        self,
        trajectory: FourierTrajectory,
        num_waypoints: int = DEFAULT_WAYPOINTS,
        name: str = "Fourier trajectory",
        redraw: bool = False,
    ):
        super().__init__(trajectory.offsets(num_waypoints), name=name)
        self.trajectory = trajectory
        self.num_waypoints = int(num_waypoints)
        self.redraw = redraw
        # In the authors' box every segment fits in one action; in a larger workspace a segment can take a few
        # steps. The cap only guards the loop: the episode ends after the last waypoint.
        self.max_steps = self.STEPS_PER_WAYPOINT * self.num_waypoints

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        if self.redraw:
            self.trajectory = FourierTrajectory.random(rng)
        self.waypoints = self.trajectory.offsets(self.num_waypoints, workspace_bound(env.config.workspace))
        super().reset(env, rng)


def random_trajectory_policy(
    num_waypoints: int = DEFAULT_WAYPOINTS, seed: int | None = 0, redraw: bool = True
) -> FourierTrajectoryPolicy:
    """The "random trajectory" baseline: a randomly parametrised Fourier loop.

    Args:
        num_waypoints: samples of the loop.
        seed: seeds the loop used before the first reset (and every episode when ``redraw`` is False).
        redraw: draw a new loop from the episode's ``rng`` at every reset, so each evaluation episode
            (sensor) gets its own random trajectory, reproducible from the evaluation seed.
    """
    trajectory = FourierTrajectory.random(np.random.default_rng(seed))
    return FourierTrajectoryPolicy(trajectory, num_waypoints, name="random trajectory", redraw=redraw)


def _fix_hint(path: Path, workspace: str, task: str) -> str:
    return (
        f"run `{FIT_COMMAND} --workspace {workspace} --tasks {task}` to (re)create it in {path}, "
        "or pass params_file= a valid file"
    )


def load_model_based_params(
    task: str, workspace: str = "paper", params_file: str | os.PathLike | None = None
) -> Mapping[str, Any]:
    """The fitted entry of ``workspace`` / ``task`` in the params file (default ``params/model_based.yaml``).

    Raises:
        ConfigError: the file is missing, unreadable, lacks the entry or its coefficients are malformed;
            the message names the file and how to recreate it.
    """
    if task not in TASKS:
        raise ConfigError(f"model-based trajectory: task must be one of {TASKS}, got {task!r}")
    path = Path(params_file) if params_file is not None else DEFAULT_PARAMS_FILE
    if not path.is_file():
        raise ConfigError(f"model-based trajectory parameters {path} not found; {_fix_hint(path, workspace, task)}")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as e:
        hint = _fix_hint(path, workspace, task)
        raise ConfigError(f"cannot read model-based trajectory parameters {path}: {e}; {hint}") from e
    fits = data.get(workspace) if isinstance(data, Mapping) else None
    entry = fits.get(task) if isinstance(fits, Mapping) else None
    if not isinstance(entry, Mapping) or "coefficients" not in entry:
        raise ConfigError(
            f"{path} has no model-based trajectory fitted for the {task} task in workspace {workspace!r}; "
            f"{_fix_hint(path, workspace, task)}"
        )
    return entry


class ModelBasedPolicy(FourierTrajectoryPolicy):
    """The PSO-fitted loop of one workspace and task; refuses to run in another workspace (``check``).

    Args:
        trajectory: the fitted loop.
        num_waypoints: samples of the loop.
        workspace: the workspace the loop was fitted in.
        task: the task it was fitted for.
    """

    def __init__(self, trajectory: FourierTrajectory, num_waypoints: int, workspace: str, task: str):
        super().__init__(trajectory, num_waypoints, name=f"model-based learned trajectory ({task})")
        self.workspace, self.task = workspace, task

    def check(self, env: CalibrationEnv) -> None:
        here = env.config.workspace.name
        if here != self.workspace:
            raise ConfigError(
                f"the model-based trajectory was fitted in workspace {self.workspace!r}, the env has workspace "
                f"{here!r}; use the fit of {here!r} (policy=model_based with workspace={here})"
            )


def model_based_policy(
    task: str, workspace: str = "paper", params_file: str | os.PathLike | None = None, num_waypoints: int | None = None
) -> ModelBasedPolicy:
    """The "model-based learned trajectory" baseline: the PSO-fitted Fourier loop of ``workspace`` and ``task``.

    Args:
        task: ``intrinsic``, ``extrinsic`` or ``joint`` (the paper's joint task runs the first two,
            one after the other).
        workspace: the workspace whose fit to use (``conf/workspace/<name>.yaml``).
        params_file: fitted coefficients (default ``vical/policies/params/model_based.yaml``, written by
            ``experiments/fit_model_based_trajectory.py``).
        num_waypoints: samples of the loop; default the number the fit used.
    """
    entry = load_model_based_params(task, workspace, params_file)
    path = Path(params_file) if params_file is not None else DEFAULT_PARAMS_FILE
    try:
        trajectory = FourierTrajectory(entry["coefficients"])
    except (TypeError, ValueError) as e:
        hint = _fix_hint(path, workspace, task)
        raise ConfigError(f"{path}: {workspace}.{task}.coefficients is malformed ({e}); {hint}") from e
    k = num_waypoints if num_waypoints is not None else int(entry.get("num_waypoints", DEFAULT_WAYPOINTS))
    return ModelBasedPolicy(trajectory, k, workspace, task)
