"""TensorBoard logging of training: namespaced scalars, env info terms, hyperparameters, trajectory plots.

Tags: ``losses/`` (SAC losses and diagnostics), ``charts/`` (episodic and evaluation returns), ``time/``
(throughput), and every numeric entry of the env's ``info`` dict whose key starts with one of the
configured prefixes (``train.info_prefixes``, by default ``calib/``, ``coverage/``, ``reward/`` and
``information/``) under its own key, so an env reports new terms without any change here.

Trajectory plots: an env may define ``trajectory_figure(observations, actions) -> matplotlib.figure.Figure``
on its unwrapped instance; otherwise the generic figure plots each observation and action component
against the step index.
"""

from __future__ import annotations

import numbers
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: figures are only rendered into TensorBoard images
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from tensorboard.compat.proto.summary_pb2 import Summary
from torch.utils.tensorboard import SummaryWriter
from torch.utils.tensorboard.summary import scalar


class TrainLogger:
    """Writes one run's TensorBoard events under ``log_dir``.

    ``purge_step``: on resume, events at or after this step are discarded so the curves continue without
    duplicates. The trainer passes the checkpoint's step + 1: a checkpoint at step S is written after
    every event of step S, so those are kept and only what the interrupted run logged after its
    checkpoint is purged.
    """

    def __init__(self, log_dir: str | Path, info_prefixes: Iterable[str], purge_step: int | None = None) -> None:
        if purge_step is not None:
            _after_existing_events(Path(log_dir))
        self.writer = SummaryWriter(str(log_dir), purge_step=purge_step)
        self.info_prefixes = tuple(info_prefixes)

    def hyperparameters(self, flat_config: Mapping[str, Any]) -> None:
        """Log the resolved config once as a markdown table (text tab)."""
        rows = "\n".join(f"|{key}|{value}|" for key, value in sorted(flat_config.items()))
        self.writer.add_text("hyperparameters", f"|param|value|\n|-|-|\n{rows}", 0)

    def scalars(self, values: Mapping[str, float], step: int) -> None:
        for tag, value in values.items():
            self.writer.add_scalar(tag, float(value), step)

    def env_info(self, info: Mapping[str, Any], step: int) -> None:
        """Log the numeric scalar entries of an env ``info`` dict whose keys start with a known prefix.

        All in one event: an env reports a dozen terms at every step, and one event per term made the
        writer's queue a measurable part of a training's time (``TrainLogger.scalars`` per tag).
        """
        values = [
            value
            for key, raw in info.items()
            if key.startswith(self.info_prefixes) and _is_scalar(raw)
            for value in scalar(key, float(raw)).value
        ]
        if values:
            self.writer._get_file_writer().add_summary(Summary(value=values), step)

    def trajectory(self, env: Any, observations: np.ndarray, actions: np.ndarray, step: int) -> None:
        """Log an episode's figure under ``charts/trajectory``: obs ``(T + 1, obs_dim)``, actions ``(T, act_dim)``."""
        hook = getattr(getattr(env, "unwrapped", env), "trajectory_figure", None)
        figure = hook(observations, actions) if callable(hook) else trajectory_figure(observations, actions)
        self.writer.add_figure("charts/trajectory", figure, step, close=True)

    def close(self) -> None:
        self.writer.close()


MAX_EVENT_WAIT = 2.0  # [s] a resumed run waits at most this long for its event file to sort last


def _after_existing_events(log_dir: Path) -> None:
    """Wait until the current second is past that of every event file in ``log_dir``.

    TensorBoard reads a folder's event files in the order of their names (``events.out.tfevents.<second>.<host>.
    <pid>.<counter>``), and a resumed run's purge applies to the events read before it: a file made in the same
    second as the interrupted run's sorts by its counter as text (10 before 9), and was read first. A file of a
    later second sorts after (the seconds have ten digits until the year 2286). A resume rarely comes within a
    second of the run it continues; when it does, this costs at most ``MAX_EVENT_WAIT``.
    """
    seconds = [
        int(p.name.split(".")[3]) for p in log_dir.glob("events.out.tfevents.*") if p.name.split(".")[3].isdigit()
    ]
    deadline = time.monotonic() + MAX_EVENT_WAIT
    while seconds and int(time.time()) <= max(seconds) and time.monotonic() < deadline:
        time.sleep(0.02)


def _is_scalar(value: Any) -> bool:
    if isinstance(value, np.ndarray):
        return value.size == 1 and np.issubdtype(value.dtype, np.number)
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def trajectory_figure(observations: np.ndarray, actions: np.ndarray) -> Figure:
    """Observation components ``(T + 1, obs_dim)`` and actions ``(T, act_dim)`` (policy units) vs step."""
    fig, (ax_obs, ax_act) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for i, series in enumerate(np.asarray(observations).T):
        ax_obs.plot(series, label=f"obs[{i}]")
    for i, series in enumerate(np.asarray(actions).T):
        ax_act.plot(series, label=f"action[{i}]")
    ax_obs.set_ylabel("observation")
    ax_act.set_ylabel("action [-1, 1]")
    ax_act.set_xlabel("step in episode")
    for ax in (ax_obs, ax_act):
        if ax.lines and len(ax.lines) <= 12:  # a legend for dozens of components is unreadable
            ax.legend(loc="upper right", fontsize="x-small", ncol=2)
    fig.tight_layout()
    return fig
