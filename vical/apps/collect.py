"""``vical-collect``: run a calibration policy on an arm holding a camera + IMU, record, calibrate it.

Configured by ``conf/collect.yaml``. The ``robot`` group builds the rig (``robot=sim``: the simulated
Panda, ``vical.sim.adapters``); the ``policy`` group the policy (the shipped learned policy of the
workspace by default), which brings the MDP it was trained in. ``vical.collection.runner.Collector``
aligns, runs the policy and writes ``<out>/recording`` (EuRoC, with the detections) as the data
arrive; then ``vical-calibrate`` calibrates it into ``<out>/calibration``. ``<out>/collect.yaml``
says what the collection did.

Exit status: 0 done; 2 a user error (a bad setting, an existing ``out``), before the robot moves; 1 the
collection stopped on a fault (a refused motion, the board lost, a broken sensor stream: the arm is
stopped, the recording so far kept and calibratable) or the calibration failed; 130 Ctrl-C (the arm
stopped, the recording closed).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import hydra
from hydra.errors import InstantiationException
from omegaconf import DictConfig

from vical.apps import calibrate
from vical.apps.cli import (
    OutputError,
    check_creatable,
    check_then_run,
    fail,
    plain,
    report_error,
    task_begins,
    write_faults_in_one_line,
)
from vical.apps.entry import interrupted_by, interrupted_status, interrupts_as_raised
from vical.apps.entry import run as run_command
from vical.calib.errors import CalibrationError
from vical.calib.tasks import CalibrationTask
from vical.collection.runner import Alignment, CollectionStopped, Collector, CollectResult, Limits, RobotEpisode
from vical.config_checks import ConfigError, from_mapping, require
from vical.data import ImuNoise, SensorTruth, Target
from vical.data.imu_grade import REAL_DATA_GRADE, ImuGrade, imu_grade
from vical.env.calibration import declared_lens_spread
from vical.env.information import Guess, LensSpread
from vical.env.reachability import check_horizon
from vical.env.settings import MdpConfig
from vical.evaluation.harness import instantiate_policy, policy_mdp
from vical.io.atomic import replace_directory, unused_sibling
from vical.io.bag import BAG_FORMATS, write_bag
from vical.io.errors import FormatError, RecordingWriteError
from vical.io.euroc import EurocStreamWriter, read_euroc
from vical.io.kalibr import (
    read_camchain,
    read_imu_grade,
    read_imu_yaml,
    read_target_yaml,
    write_imu_yaml,
    write_target_yaml,
)
from vical.io.yamlfile import dump_yaml
from vical.policies.base import Policy
from vical.policies.stopping import StopRule, with_stop
from vical.robot import MotionRefused, SensorStreamError
from vical.sim.sampling import SensorSampling
from vical.sim.settings import SimConfig

APP = "vical-collect"
USER_ERRORS = (ConfigError, FileExistsError, FileNotFoundError, OutputError)
FAULTS = (CollectionStopped, MotionRefused, SensorStreamError, RecordingWriteError)
EXIT_FAULT = 1
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


@dataclass(frozen=True)
class CollectionOutput:
    """Where a collection goes and what calibrates it (``check_output``): the settings ``vical-collect``'s
    ``CollectSettings`` and ``vical.apps.guide.GuideSettings`` share, and all that the writing and the calibration
    read of them."""

    out: Path
    overwrite: bool
    task: str
    camchain: Path | None
    imu_yaml: Path | None
    rolling_shutter: bool


@dataclass(frozen=True)
class CollectSettings(CollectionOutput):
    """The checked settings of a collection."""

    align: Alignment
    limits: Limits
    bag: str | None  # the bag the recording is also written as (``BAG_FORMATS``), or None


# Where ``bag=`` writes each kind of bag in ``out``: Kalibr's ROS1 file, or a ROS 2 bag's folder.
BAG_NAMES = {kind: "recording.bag" if kind == "ros1" else "recording_ros2" for kind in BAG_FORMATS}


def _bag_format(value: Any) -> str | None:
    """``bag=``'s format: false/null (none), true (ros1, Kalibr's), ros1, db3 or mcap; ``ConfigError`` otherwise."""
    if value is None or value is False:
        return None
    if value is True:
        return "ros1"
    if value not in BAG_NAMES:
        raise ConfigError(f"bag={value}: choose false, ros1 (true; the bag Kalibr reads), db3 or mcap (a ROS 2 bag)")
    return str(value)


def _existing_file(value: Any, key: str) -> Path | None:
    if value is None:
        return None
    path = Path(str(value))
    if not path.is_file():
        raise FileNotFoundError(f"{key}={value}: no such file")
    return path


def _readable_file(value: Any, key: str, reader) -> Path | None:
    """``_existing_file`` that ``reader`` also reads: a file it refuses is a ``ConfigError`` naming ``key``, before
    anything connects."""
    path = _existing_file(value, key)
    if path is not None:
        try:
            reader(path)
        except FormatError as err:
            why = str(err).removeprefix(str(path)).lstrip(" :")
            raise ConfigError(f"{key}={value}: {why}") from None
    return path


def _imu_declaration(path: Path) -> tuple[ImuNoise, ImuGrade | None]:
    """What an imu.yaml declares: the noise densities and the grade (either's bad keys refused)."""
    return read_imu_yaml(path), read_imu_grade(path)


def check_settings(cfg: DictConfig) -> CollectSettings:
    """The settings of ``cfg``, checked before anything connects; ``ConfigError`` naming the key otherwise."""
    try:
        align = from_mapping(Alignment, plain(cfg.align), "align")
        limits = from_mapping(Limits, plain(cfg.limits), "limits")
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return CollectSettings(align=align, limits=limits, bag=_bag_format(cfg.get("bag")), **check_output(cfg))


def check_output(cfg: DictConfig) -> dict[str, Any]:
    """The settings ``vical-collect`` and ``vical-guide`` share (where the collection goes, what is calibrated from
    which nominal files), checked: ``out``, ``overwrite``, ``task``, ``camchain``, ``imu_yaml``,
    ``rolling_shutter``."""
    out = cfg.get("out")
    require(isinstance(out, str) and bool(out), "out", "a directory path", out)
    overwrite = bool(cfg.get("overwrite"))
    path = Path(out)
    if path.exists() and not overwrite and (not path.is_dir() or any(path.iterdir())):
        raise FileExistsError(f"out={out} already exists; choose another directory or pass overwrite=true")
    check_creatable("out=", path)
    task = cfg.task.name
    guess = plain(cfg.get("guess")) or {}
    camchain = _readable_file(guess.get("camchain"), "guess.camchain", read_camchain)
    if task == "extrinsic" and camchain is None:
        raise ConfigError("the extrinsic task calibrates with known intrinsics: pass guess.camchain=<camchain.yaml>")
    rolling = cfg.get("rolling_shutter", False)
    require(isinstance(rolling, bool), "rolling_shutter", "true or false", rolling)
    imu_yaml = _readable_file(guess.get("imu_yaml"), "guess.imu_yaml", _imu_declaration)
    return {"out": path, "overwrite": overwrite, "task": task, "camchain": camchain, "imu_yaml": imu_yaml,
            "rolling_shutter": rolling}  # fmt: skip


def mdp_config(cfg: DictConfig, policy: Policy) -> MdpConfig:
    """The MDP the policy runs in: the ``env`` group's, with what the policy brings (as ``vical-evaluate`` does)."""
    env = {k: v for k, v in plain(cfg.env).items() if k not in ("_target_", "sim", "sensor", "task")}
    return MdpConfig.from_config({**env, **policy_mdp(policy)})


def nominal_sensor(s: CollectionOutput, rig: Any) -> SensorTruth:
    """The sensor's nominal values: the ``guess`` files, else the adapter's datasheet; its IMU grade as the
    calibration of the recording will count it (``declared_grade``)."""
    datasheet: SensorTruth | None = getattr(rig, "datasheet", None)
    if datasheet is None and (s.camchain is None or s.imu_yaml is None):
        raise ConfigError(
            "the robot adapter knows no nominal values of the sensor: pass guess.camchain=<camchain.yaml> "
            "and guess.imu_yaml=<imu.yaml> (a datasheet calibration and the IMU's noise densities)"
        )
    camera, T_cam_imu, shift = (datasheet.camera, datasheet.T_cam_imu, datasheet.time_offset) if datasheet else (
        None, None, None)  # fmt: skip
    if s.camchain is not None:
        camera, T_file, shift_file = read_camchain(s.camchain)
        T_cam_imu = T_file if T_file is not None else T_cam_imu
        shift = shift_file if shift_file is not None else shift
    if T_cam_imu is None:
        raise ConfigError(f"guess.camchain={s.camchain} holds no T_cam_imu; write the nominal extrinsic into it")
    noise = read_imu_yaml(s.imu_yaml) if s.imu_yaml is not None else datasheet.imu_noise
    grade = declared_grade(s, rig)  # none declared: what vical-calibrate will count, a real IMU's default
    return SensorTruth(camera, T_cam_imu, shift or 0.0, noise, imu_grade=grade or imu_grade(REAL_DATA_GRADE))


def declared_grade(s: CollectionOutput, rig: Any) -> ImuGrade | None:
    """The IMU grade the sensor declares: ``guess.imu_yaml``'s, else the adapter's datasheet's; None where neither
    declares one (the calibration then takes a real IMU's default)."""
    declared = read_imu_grade(s.imu_yaml) if s.imu_yaml is not None else None
    datasheet: SensorTruth | None = getattr(rig, "datasheet", None)
    return declared if declared is not None or datasheet is None else datasheet.imu_grade


def write_calibration_inputs(s: CollectionOutput, target: Target, nominal: SensorTruth, rig: Any) -> None:
    """``<out>/target.yaml`` and ``<out>/imu.yaml`` (the nominal noise densities, the declared grade): what the
    calibration of the recording reads (``calibrate_hint``)."""
    s.out.mkdir(parents=True, exist_ok=True)
    write_target_yaml(s.out / "target.yaml", target)
    write_imu_yaml(s.out / "imu.yaml", nominal.imu_noise, grade=declared_grade(s, rig))


def build_robot(robot: DictConfig, group: str = "robot") -> Any:
    """The ``group`` config group's rig (``robot``; vical-guide's ``person``); what its adapter refuses (a bad
    setting, a missing extra, a robot or sensor it cannot reach) is a ``ConfigError``."""
    try:
        return hydra.utils.instantiate(robot, _convert_="all")
    except InstantiationException as err:
        cause = err.__cause__
        if isinstance(cause, ValueError | ImportError | ConnectionError):
            raise ConfigError(f"{group}: {cause}") from None
        raise


def aside(out: Path) -> Path:
    """Where a run collects: ``out`` when nothing is there, else a fresh sibling (``overwrite=true`` over a
    collection: it replaces the old one once complete, ``replace_directory``)."""
    if not out.exists():
        return out
    return unused_sibling(out, "new")


def configured_policy(cfg: DictConfig, task: str, name: str | None = None) -> Policy:
    """The ``policy`` group's policy for ``task`` with the ``stop`` group's stopping rule (``vical-collect``'s and
    ``vical-guide``'s); ``name`` (None: the group's own) labels it."""
    policy = instantiate_policy(plain(cfg.policy)[task], name or cfg.policy.get("name", "policy"))
    return with_stop(policy, StopRule.from_config(plain(cfg.get("stop"))))


def collect(cfg: DictConfig) -> int:
    """Collect and calibrate as ``cfg`` says; the exit status (module doc)."""
    s = check_settings(cfg)
    policy = configured_policy(cfg, s.task)
    mdp = mdp_config(cfg, policy)
    policy.check(RobotEpisode(mdp))  # before connecting: a policy of another workspace or state
    check_horizon(s.limits.horizon_s, "limits.horizon_s", mdp.reset_hold, RobotEpisode(mdp).step_timing)
    rig = build_robot(cfg.robot)
    try:
        nominal = nominal_sensor(s, rig)
        if cfg.get("dry_run"):
            _dry_run(cfg, s, rig, policy, mdp, nominal)
            return 0
        final, s = s.out, replace(s, out=aside(s.out))  # a collection there is replaced only by a complete one
        result = _run(cfg, s, rig, policy, mdp, nominal)
    finally:
        rig.close()
    if result is None:
        return EXIT_FAULT
    status = calibrate_or_stop(s, result, bool(cfg.get("report"))) if cfg.get("calibrate") else 0
    if s.out != final:
        replace_directory(s.out, final)
        print(f"the collection in {final} is replaced by this one (the paths above, under {s.out}, are now under it)")
    return status


def build_collector(
    cfg: DictConfig,
    s: CollectSettings,
    rig: Any,
    policy: Policy,
    mdp: MdpConfig,
    nominal: SensorTruth,
    recording: Path | None,
    progress: Callable[[str], None] | None = None,
) -> Collector:
    """The runner of ``vical-collect`` on ``rig``, writing the EuRoC folder ``recording`` (None: the dry run's,
    which writes nothing); ``progress`` defaults to printing when ``cfg.progress``."""
    sensor = rig.sensor
    writer = None if recording is None else EurocStreamWriter(
        recording, sensor.image_size, sensor.camera_rate_hz, sensor.imu_rate_hz, nominal.imu_noise)  # fmt: skip
    guess = Guess(nominal.camera, nominal.T_cam_imu, nominal.time_offset, nominal.imu_noise,
                  mdp.information.pixel_sigma, lens_spread(cfg, mdp, nominal), nominal.imu_grade)  # fmt: skip
    if progress is None:
        progress = print if cfg.get("progress") else (lambda line: None)
    return Collector(rig.arm, sensor, policy, mdp, s.task, board(cfg, rig), guess, writer, s.align, s.limits,
                     progress)  # fmt: skip


def lens_spread(cfg: DictConfig, mdp: MdpConfig, nominal: SensorTruth) -> LensSpread | None:
    """The decentred lens the policy's state considers, as in its training env (the ``sensor`` group's spreads)."""
    sampling = SensorSampling.from_config(plain(cfg.sensor)).camera
    task = CalibrationTask.from_config(plain(cfg.task))
    return declared_lens_spread(mdp.information, nominal.camera, sampling, task)


def board(cfg: DictConfig, rig: Any) -> Target:
    """The calibration target: the rig's when it knows it (a simulated rig's drawn board, ``sensor.products``),
    else the board the workspace group describes (``sim.board``)."""
    target = getattr(rig, "target", None)
    return target if target is not None else SimConfig.from_mapping(plain(cfg.sim)).board.target


def _dry_run(cfg: DictConfig, s: CollectSettings, rig: Any, policy: Policy, mdp: MdpConfig, nominal: SensorTruth):
    """Connect, read the arm and the streams, locate the board; move nothing, write nothing."""
    print(f"{APP}: dry run: reading the arm and the sensor for {cfg.dry_run_seconds} s; nothing moves")
    with rig.arm, rig.sensor:
        build_collector(cfg, s, rig, policy, mdp, nominal, None).dry_run(float(cfg.dry_run_seconds))


def _run(cfg: DictConfig, s: CollectSettings, rig: Any, policy: Policy, mdp: MdpConfig, nominal: SensorTruth):
    """The collection; None when it stopped on a fault (reported), the result otherwise."""
    write_calibration_inputs(s, board(cfg, rig), nominal, rig)
    collector = build_collector(cfg, s, rig, policy, mdp, nominal, s.out / "recording")
    writer = collector.stream.writer
    try:
        with interrupts_as_raised(), rig.arm, rig.sensor:  # a lock an interrupt left half released: the interrupt
            result = collector.run(int(cfg.seed))
    except FAULTS as err:
        with contextlib.suppress(OSError):  # a full disk (the fault, maybe) takes neither; the line below says why
            write_summary(s, None, f"stopped: {err}", writer.frames)
            _write_bag(s)
        report_error(APP, f"stopped: {err}; the arm is stopped and {recording_kept(s, writer)}")
        return None
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM (vical.apps.entry)
        write_summary(s, None, f"interrupted ({interrupted_by(err)})", writer.frames)
        print(f"{APP}: interrupted ({interrupted_by(err)}): the arm is stopped and {recording_kept(s, writer)}",
              file=sys.stderr)  # fmt: skip
        raise SystemExit(interrupted_status(err)) from None
    write_summary(s, result, f"done: {result.reason}", writer.frames)
    if result.out_of_reach is not None:  # the reason, whatever the progress lines: what to change, and where
        print(f"{APP}: {result.reason} (collect.yaml: out_of_reach)", file=sys.stderr)
    _write_bag(s)
    return result


def _write_bag(s: CollectSettings) -> None:
    """``bag=``: the recording also as a bag with Kalibr's topics, ROS1 or ROS 2 (``BAG_NAMES``; written whole,
    from the EuRoC folder, which is what survives a kill)."""
    if s.bag is None or not (s.out / "recording" / "mav0" / "cam0" / "data.csv").is_file():
        return
    try:
        recording = read_euroc(s.out / "recording", read_target_yaml(s.out / "target.yaml"))
    except FormatError as err:  # no frame recorded yet
        print(f"{APP}: no bag written: {err}", file=sys.stderr)
        return
    print(f"bag written to {write_bag(recording, s.out / BAG_NAMES[s.bag], bag_format=s.bag)}")


def _calibrate_args(s: CollectionOutput) -> list[str]:
    args = [str(s.out / "recording"), "--task", s.task, "--target", str(s.out / "target.yaml"), "--stored-corners"]
    if s.task != "intrinsic":
        args += ["--imu-yaml", str(s.out / "imu.yaml")]
    if s.camchain is not None and s.task == "extrinsic":
        args += ["--intrinsics", str(s.camchain)]
    if s.rolling_shutter and s.task != "intrinsic":
        args += ["--rolling-shutter"]
    return args + ["--out", str(s.out / "calibration")]


def calibrate_hint(s: CollectionOutput) -> str:
    return "calibrate it with: vical-calibrate " + " ".join(_calibrate_args(s))


def recording_kept(s: CollectionOutput, writer: EurocStreamWriter) -> str:
    """What a stopped collection leaves: where its recording is and how to calibrate it, or that it holds no frame."""
    if writer.frames == 0:
        return f"no frame was recorded ({writer.path}): nothing to calibrate"
    return f"the recording so far is in {writer.path} ({writer.frames} frames): {calibrate_hint(s)}"


def calibrate_or_stop(s: CollectionOutput, result: CollectResult, report: bool) -> int:
    """``_calibrate``; an interrupt there keeps the recording, says how to calibrate it, and is recorded in
    ``collect.yaml``."""
    try:
        return _calibrate(s, report)
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM (vical.apps.entry)
        by = interrupted_by(err)
        write_summary(s, result, f"done: the recording; the calibration interrupted ({by})", result.frames)
        print(f"{APP}: interrupted ({by}) in the calibration: the recording is in {s.out}: {calibrate_hint(s)}",
              file=sys.stderr)  # fmt: skip
        raise SystemExit(interrupted_status(err)) from None


def _calibrate(s: CollectionOutput, report: bool) -> int:
    """``vical-calibrate`` on the recording; its exit status (1 when it failed)."""
    status = calibrate.main(_calibrate_args(s) + ([] if report else ["--no-report"]))
    return 0 if status == 0 else EXIT_FAULT


def write_summary(s: CollectionOutput, result: CollectResult | None, outcome: str, frames: int) -> None:
    """``collect.yaml``: how the collection ended; for a finished one, its numbers, the verdict of a run stopped as out
    of reach and each goal group's forecast (its ratio to tolerance, the recording it needs, its ratio at the
    horizon)."""
    summary: dict[str, Any] = {"outcome": outcome, "frames": frames, "task": s.task}
    if result is not None:
        summary.update({"steps": result.steps, "path_length_m": round(result.path_length, 4),
                        "duration_s": round(result.duration, 3), "goal_reached": result.goal_reached})  # fmt: skip
        if result.out_of_reach is not None:
            summary["out_of_reach"] = result.out_of_reach.as_dict()
        if result.forecast:
            summary["forecast"] = {g: f.as_dict() for g, f in result.forecast.items()}
    dump_yaml(s.out / "collect.yaml", summary)


# What a collection keeps when the disk takes no more outside the recording (whose own writer says how far it got).
KEPT_WHOLE = (
    "what it holds is whole (each file is written whole or not at all) and a collection it replaces is as it was"
)


def finish(app: str, work: Callable[[DictConfig], int], cfg: DictConfig) -> None:
    """A collection app's ``work`` under Hydra: a user error is one line and status 2, a failed calibration one line
    and 1, otherwise the work's status (``vical-collect``'s and ``vical-guide``'s)."""
    task_begins()
    try:
        with write_faults_in_one_line(app, "out=", cfg.out, KEPT_WHOLE):
            status = work(cfg)
    except USER_ERRORS as err:
        fail(app, err)
    except CalibrationError as err:
        raise SystemExit(report_error(app, err)) from None
    if status:
        raise SystemExit(status)


@hydra.main(config_path=CONF_DIR, config_name="collect", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    finish(APP, collect, cfg)


def main() -> None:
    """Console entry point: the settings, and Hydra's own override errors, are checked before Hydra runs."""
    check_then_run(APP, CONF_DIR, "collect", check_settings, hydra_main, USER_ERRORS)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
