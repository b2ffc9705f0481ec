"""``vical-imu-noise``: an IMU's noise densities and bias random walks from a static recording (Allan deviation).

Examples::

    vical-imu-noise static_euroc --out imu_noise              # EuRoC folder: imu0/data.csv (or mav0/imu0/)
    vical-imu-noise static.bag --imu-topic /imu0 --out imu_noise
    vical-imu-noise imu0.csv --rate 200 --start 60 --out imu_noise

Record the IMU lying still (on a table, away from fans and footsteps) for hours: the random walk is
read from the rise of the Allan deviation at long averaging times, and a recording too short to show
it is refused with the duration it needs. The method and its accuracy: ``vical.calib.noise.allan`` and
``docs/sensors.md``.

Outputs in ``--out``, written as one directory atomically (an ``--out`` that holds files is refused
unless ``--overwrite``):

- ``imu.yaml``: Kalibr's IMU file with the measured values (per sensor, the largest of its three axes);
- ``imu-inflated.yaml``: the same values inflated (``--inflate-density``, ``--inflate-walk``), as
  practice advises for Kalibr's camera-IMU calibration;
- ``allan.yaml``: per axis the noise density, random walk, bias instability and the Allan deviation;
- ``allan.png``: the Allan plot with the fitted lines.

Units: gyro noise density rad/s/sqrt(Hz), random walk rad/s^2/sqrt(Hz), bias instability rad/s;
accelerometer m/s^2/sqrt(Hz), m/s^3/sqrt(Hz), m/s^2. User errors print one line ``vical-imu-noise:
error: ...`` and exit with status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from vical.apps.calibrate import _number, check_out
from vical.apps.cli import ArgumentParser, OutputError, argparse_main, cannot_write
from vical.apps.entry import run as run_command
from vical.calib.noise.allan import (
    AXES,
    AxisNoise,
    NoiseIdentification,
    NoiseIdentificationError,
    averaging_factors,
    identify_noise,
    inflate,
    sample_rate,
)
from vical.calib.noise.allan_plot import write_allan_png
from vical.data import NS_PER_S, DataError, ImuNoise, ImuSamples
from vical.io.atomic import atomic_directory
from vical.io.errors import FormatError
from vical.io.kalibr import write_imu_yaml
from vical.io.sources import open_imu
from vical.io.yamlfile import dump_yaml

APP = "vical-imu-noise"
FLAGS = {"gyro_unit": "--gyro-unit", "accel_unit": "--accel-unit"}
RATE_TOLERANCE = 0.02  # a --rate further than this from the timestamps' rate is a mistake in one of them
# [rad/s/sqrt(Hz)] the gyro noise densities of real gyros: a navigation-grade gyro's angle random walk is about
# 0.002 deg/sqrt(h) (5.8e-7), the noisiest MEMS gyros' about 0.3 deg/s/sqrt(Hz) (5.2e-3); a gyro logged in deg/s and
# read as rad/s lies 57x above its true value, one logged in rad/s and read as deg/s 57x below.
REAL_GYRO_DENSITY = (5e-7, 5e-3)
UNIT_NOTE = (
    "units: noise densities rad/s/sqrt(Hz) (gyro), m/s^2/sqrt(Hz) (accel); random walks rad/s^2/sqrt(Hz), "
    "m/s^3/sqrt(Hz); update_rate Hz"
)


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog=APP, description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="static IMU recording: EuRoC folder, EuRoC IMU CSV, ROS1 or ROS 2 bag")
    p.add_argument("--imu-topic", default="/imu0", help="bag IMU topic, also written as rostopic (default: /imu0)")
    p.add_argument("--gyro-unit", choices=("rad/s", "deg/s"), default="rad/s", help="gyro unit in the file")
    p.add_argument("--accel-unit", choices=("m/s^2", "g"), default="m/s^2", help="accelerometer unit in the file")
    p.add_argument("--rate", type=_number(0, closed=False), help="the IMU's nominal rate [Hz], checked and written")
    p.add_argument("--start", type=_number(0), default=0.0, help="[s] skip this much of the start (warm-up, set-up)")
    p.add_argument("--end", type=_number(0, closed=False), help="[s] use the recording up to this time")
    p.add_argument(
        "--inflate-density", type=_number(1), default=10.0, help="factor on the noise densities (default: 10)"
    )
    p.add_argument("--inflate-walk", type=_number(1), default=20.0, help="factor on the random walks (default: 20)")
    p.add_argument("--out", default="imu_noise", help="output directory (default: ./imu_noise)")
    p.add_argument("--overwrite", action="store_true", help="replace an --out that holds files (as a whole)")
    return p


def load(args: argparse.Namespace) -> ImuSamples:
    """The recording's IMU samples between ``--start`` and ``--end``."""
    imu = open_imu(args.recording, args.imu_topic, args.gyro_unit, args.accel_unit)
    if len(imu) == 0:
        raise FormatError(f"{args.recording} holds no IMU samples")
    if len(imu) == 1:
        raise NoiseIdentificationError(
            f"{args.recording} holds one IMU sample: the noise identification needs hours of a resting IMU"
        )
    span = (imu.t[-1] - imu.t[0]) / NS_PER_S
    end = span if args.end is None else args.end
    if args.start >= min(end, span):
        raise NoiseIdentificationError(
            f"--start {args.start:g} s leaves nothing of the {span:.1f} s recording"
            + (f" before --end {args.end:g} s" if args.end is not None else "")
        )
    t0 = int(imu.t[0])
    return imu.slice_time(t0 + round(args.start * NS_PER_S), t0 + round(end * NS_PER_S))


def check_rate(args: argparse.Namespace, imu: ImuSamples) -> float:
    """[Hz] the rate to write: ``--rate`` when it agrees with the timestamps, else their rate."""
    measured = sample_rate(imu, args.recording)
    if args.rate is not None and abs(measured / args.rate - 1) > RATE_TOLERANCE:
        raise NoiseIdentificationError(
            f"--rate {args.rate:g} Hz disagrees with the timestamps of {args.recording}, which say {measured:.4g} Hz "
            f"(median interval {1e3 / measured:.4g} ms): correct --rate, or check that the timestamps are in ns"
        )
    return measured if args.rate is None else args.rate


def identify(imu: ImuSamples, where: str) -> NoiseIdentification:
    """``identify_noise`` with a progress bar (on stderr) over the averaging times of the six axes."""
    total = len(AXES) * len(averaging_factors(len(imu)))
    with tqdm(total=total, desc="Allan deviation", unit="tau", leave=False) as bar:
        return identify_noise(imu, where, progress=bar.update)


def inflated_comment(density: float, walk: float) -> str:
    """The header of ``imu-inflated.yaml``: the factors, why, and the units."""
    return (
        f"vical-imu-noise: the measured values of imu.yaml inflated, noise densities x{density:g}, random walks "
        f"x{walk:g}.\nA static recording misses what motion adds (vibration, temperature change, scale and "
        "misalignment errors),\nso practice (Kalibr's wiki) inflates the Allan values for camera-IMU calibration; "
        f"see docs/sensors.md.\n{UNIT_NOTE}"
    )


def axis_entry(axis: AxisNoise) -> dict:
    """One axis of ``allan.yaml``: its values and its Allan deviation curve."""
    return {
        "noise_density": axis.noise_density,
        "random_walk": axis.random_walk,
        "bias_instability": axis.bias_instability,
        "tau_of_minimum": axis.tau_min,
        "tau": [float(v) for v in axis.curve.tau],
        "allan_deviation": [float(v) for v in axis.curve.adev],
    }


def write_outputs(out: Path, result: NoiseIdentification, measured: ImuNoise, args: argparse.Namespace) -> None:
    """Write every output into ``out`` at once (replacing it whole)."""
    inflated = inflate(measured, args.inflate_density, args.inflate_walk)
    source = f"vical-imu-noise: Allan deviation of {args.recording} ({result.duration_s / 3600:.2f} h)"
    report = {
        "rate_hz": result.rate_hz,
        "duration_s": result.duration_s,
        "units": {"gyro": "rad/s, N rad/s/sqrt(Hz), K rad/s^2/sqrt(Hz), B rad/s, tau s",
                  "accel": "m/s^2, N m/s^2/sqrt(Hz), K m/s^3/sqrt(Hz), B m/s^2, tau s"},
        "axes": {axis.axis: axis_entry(axis) for axis in result.axes},
    }  # fmt: skip
    try:
        with atomic_directory(out, overwrite=out.exists()) as tmp:
            comment = f"{source}; per sensor the largest of its three axes (allan.yaml).\n{UNIT_NOTE}"
            write_imu_yaml(tmp / "imu.yaml", measured, args.imu_topic, comment)
            write_imu_yaml(
                tmp / "imu-inflated.yaml",
                inflated,
                args.imu_topic,
                inflated_comment(args.inflate_density, args.inflate_walk),
            )
            dump_yaml(
                tmp / "allan.yaml",
                report,
                comment=f"{source}; N read at tau = 1 s, K at tau = 3 s, B = minimum / 0.664",
            )
            write_allan_png(tmp / "allan.png", result)
    except OSError as err:
        raise OutputError(cannot_write("--out", out, err)) from None


def summary(result: NoiseIdentification, measured: ImuNoise, inflated: ImuNoise) -> str:
    """The table printed at the end: the values per axis, then what the two Kalibr files hold."""
    lines = [
        f"recording            {result.duration_s / 3600:.2f} h at {result.rate_hz:.4g} Hz",
        "axis      noise density   random walk    bias instability  at tau [s]",
    ]
    for axis in result.axes:
        lines.append(
            f"{axis.axis:<9} {axis.noise_density:<15.4g} {axis.random_walk:<14.4g} {axis.bias_instability:<17.4g} "
            f"{axis.tau_min:.3g}"
        )
    lines.append("units: gyro rad/s/sqrt(Hz), rad/s^2/sqrt(Hz), rad/s; accel m/s^2/sqrt(Hz), m/s^3/sqrt(Hz), m/s^2")
    for name, noise in (("imu.yaml", measured), ("imu-inflated.yaml", inflated)):
        lines.append(
            f"{name:<18} gyroscope {noise.gyro_noise_density:.4g} / {noise.gyro_random_walk:.4g}, "
            f"accelerometer {noise.accel_noise_density:.4g} / {noise.accel_random_walk:.4g} (density / random walk)"
        )
    return "\n".join(lines)


def gyro_unit_warnings(measured: ImuNoise, gyro_unit: str) -> list[str]:
    """A warning naming the likely unit when the gyro's density is beyond the range of real gyros."""
    density, (low, high) = measured.gyro_noise_density, REAL_GYRO_DENSITY
    real = f"real gyros lie between {low:g} (navigation grade) and {high:g} (the noisiest MEMS)"
    if density > high and gyro_unit == "rad/s":
        return [f"gyroscope_noise_density {density:.3g} rad/s/sqrt(Hz) is above any real gyro ({real}): the file "
                "likely logs deg/s; pass --gyro-unit deg/s"]  # fmt: skip
    if density < low and gyro_unit == "deg/s":
        return [f"gyroscope_noise_density {density:.3g} rad/s/sqrt(Hz) is below any real gyro ({real}): the file "
                "likely logs rad/s; leave out --gyro-unit deg/s"]  # fmt: skip
    return []


def run(args: argparse.Namespace) -> NoiseIdentification:
    """Identify the noise as the parsed arguments say, write the outputs and print the summary."""
    out = Path(args.out)
    check_out(out, args.overwrite, [args.recording])
    imu = load(args)
    rate = check_rate(args, imu)
    result = identify(imu, args.recording)
    measured = result.imu_noise(rate)
    write_outputs(out, result, measured, args)
    for warning in gyro_unit_warnings(measured, args.gyro_unit):
        print(f"warning: {warning}")
    print(summary(result, measured, inflate(measured, args.inflate_density, args.inflate_walk)))
    print(f"outputs written to {out}")
    return result


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input)."""
    errors = (NoiseIdentificationError, FormatError, DataError, OutputError)
    return argparse_main(APP, build_parser(), run, errors, FLAGS, argv)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
