"""The calibration episode as a figure: image coverage and the end-effector path (TensorBoard)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from vical.env.information import FEATURE_DECADES

POLYGON = slice(0, 8)
POSE = slice(18, 24)
INFO_POSE = slice(6, 12)  # the information state: six group values, then the pose offset


def episode_figure(observations: np.ndarray, bound: np.ndarray) -> Figure:
    """Coverage polygon per step in the image and the position offsets [m] (states (T + 1, 24))."""
    obs = np.asarray(observations, dtype=float)
    fig, (ax_img, ax_path) = plt.subplots(1, 2, figsize=(9, 3.8))
    colors = plt.cm.viridis(np.linspace(0.0, 1.0, len(obs)))
    for k, (state, color) in enumerate(zip(obs, colors, strict=True)):
        poly = state[POLYGON].reshape(4, 2)
        closed = np.vstack([poly, poly[:1]])
        ax_img.plot(closed[:, 0], closed[:, 1], color=color, lw=2.0 if k == len(obs) - 1 else 0.8)
    ax_img.set(xlim=(0, 1), ylim=(1, 0), xlabel="u / W", ylabel="v / H", title="board-centre coverage")
    ax_img.axhline(0.5, color="grey", lw=0.5)
    ax_img.axvline(0.5, color="grey", lw=0.5)
    position = (obs[:, POSE][:, :3] * 2.0 - 1.0) * bound[:3]
    for i, name in enumerate("xyz"):
        ax_path.plot(position[:, i] * 1e3, marker=".", label=name)
    ax_path.set(xlabel="step", ylabel="offset from start [mm]", title="end-effector position")
    ax_path.legend(fontsize="small")
    fig.tight_layout()
    return fig


def information_figure(observations: np.ndarray, bound: np.ndarray, groups: tuple[str, ...]) -> Figure:
    """Each group's predicted error over its tolerance per step (log scale) and the position offsets [m]."""
    obs = np.asarray(observations, dtype=float)
    fig, (ax_info, ax_path) = plt.subplots(1, 2, figsize=(9, 3.8))
    for k, group in enumerate(groups):
        if np.any(obs[:, k] > 0):  # a group the task estimates
            ax_info.plot(10.0 ** ((obs[:, k] - 0.5) * FEATURE_DECADES), marker=".", label=group)
    ax_info.axhline(1.0, color="grey", lw=0.8)
    ax_info.set(yscale="log", xlabel="step", ylabel="error quantile / tolerance", title="information state")
    ax_info.legend(fontsize="x-small")
    position = (obs[:, INFO_POSE][:, :3] * 2.0 - 1.0) * bound[:3]
    for i, name in enumerate("xyz"):
        ax_path.plot(position[:, i] * 1e3, marker=".", label=name)
    ax_path.set(xlabel="step", ylabel="offset from start [mm]", title="end-effector position")
    ax_path.legend(fontsize="small")
    fig.tight_layout()
    return fig
