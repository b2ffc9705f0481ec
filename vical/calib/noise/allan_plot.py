"""The Allan plot of a noise identification: log-log deviation per axis with the lines its values are read from."""

from __future__ import annotations

import os

import numpy as np
from matplotlib.figure import Figure  # no pyplot: no global backend state, no display needed

from vical.calib.noise.allan import BIAS_INSTABILITY_FACTOR, NoiseIdentification
from vical.io.atomic import atomic_file

COLORS = ("tab:red", "tab:green", "tab:blue")
# (sensor, unit of the readings, of its noise density, of its random walk)
SENSORS = (
    ("gyro", "rad/s", "rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)"),
    ("accel", "m/s^2", "m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)"),
)


def allan_figure(result: NoiseIdentification) -> Figure:
    """Gyro and accelerometer panels: each axis's Allan deviation (solid), its -1/2 line read at tau = 1 s,
    its +1/2 line read at tau = 3 s (dashed) and its flat minimum (dotted)."""
    fig = Figure(figsize=(11, 4.8))
    for ax, (sensor, unit, density_unit, walk_unit) in zip(fig.subplots(1, 2), SENSORS, strict=True):
        for axis, color in zip(result.sensor(sensor), COLORS, strict=True):
            tau = axis.curve.tau
            ax.loglog(tau, axis.curve.adev, color=color, lw=1.6, label=f"{axis.axis}")
            ax.loglog(tau, axis.white_line(tau), color=color, ls="--", lw=0.9)
            ax.loglog(tau, axis.walk_line(tau), color=color, ls="--", lw=0.9)
            ax.axhline(axis.bias_instability * BIAS_INSTABILITY_FACTOR, color=color, ls=":", lw=0.9)
            ax.plot([1.0, 3.0], [axis.white_line(1.0), axis.walk_line(3.0)], "o", color=color, ms=4)
        ax.set_ylim(_limits([a.curve.adev for a in result.sensor(sensor)]))
        ax.set_xlabel("averaging time tau [s]")
        ax.set_ylabel(f"Allan deviation [{unit}]")
        noise = result.imu_noise()
        density = getattr(noise, f"{sensor}_noise_density")
        walk = getattr(noise, f"{sensor}_random_walk")
        ax.set_title(f"{sensor}: N = {density:.3g} {density_unit}, K = {walk:.3g} {walk_unit}", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, title="dashed: N / sqrt(tau), K sqrt(tau/3); dotted: 0.664 B", title_fontsize=7)
    fig.suptitle(
        f"Allan deviation of a {result.duration_s / 3600:.2f} h static recording at {result.rate_hz:.4g} Hz "
        "(dots: N read at tau = 1 s, K at tau = 3 s)",
        fontsize=10,
    )
    fig.tight_layout()
    return fig


def _limits(curves: list[np.ndarray]) -> tuple[float, float]:
    """y range of the measured curves with a margin (the fitted lines run off it)."""
    values = np.concatenate(curves)
    return float(values.min() / 3), float(values.max() * 3)


def write_allan_png(path: str | os.PathLike, result: NoiseIdentification) -> None:
    """Write ``allan_figure`` as a PNG, atomically."""
    with atomic_file(path) as tmp:
        allan_figure(result).savefig(tmp, format="png", dpi=110)
