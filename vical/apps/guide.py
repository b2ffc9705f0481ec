"""``vical-guide``: guide a person who holds the camera + IMU, live, until the calibration is predicted good enough;
record, calibrate.

Configured by ``conf/guide.yaml``. The ``person`` group builds who holds which sensor (``person=sim``: a simulated
person with the simulated sensor, ``vical.sim.hand_held``; ``person=realsense`` / ``person=ros``: you, with a
RealSense or a sensor on ROS topics); the ``policy`` group the policy that decides where to go next (by default
the information-rate planner, ``policy=rate_planner``, pricing a step at the person's reach, ``reach``;
``policy=learned_person`` the learned policy trained with a simulated person). The guide
(``vical.collection.guide.Guide``) shows each next pose on a local web page (``vical.collection.page``: the live
image with the board's outline where it should appear, the instruction in words, a bar per parameter group, the
time, "done") and as progress lines; it writes ``<out>/recording`` (EuRoC, with the detections) as the data arrive,
then ``vical-calibrate`` calibrates it into ``<out>/calibration``, and the page shows the result.

Exit status: 0 done; 2 a user error (a bad setting, an existing ``out``, a port in use), before anything starts;
1 the guide stopped on a fault (the board lost, a broken sensor stream, the page's tab closed: the recording so far
is kept and calibratable) or the calibration failed; 130 Ctrl-C (the recording closed).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import hydra
from omegaconf import DictConfig

from vical.apps.cli import check_then_run, plain, report_error
from vical.apps.collect import (
    EXIT_FAULT,
    FAULTS,
    USER_ERRORS,
    CollectionOutput,
    aside,
    board,
    build_robot,
    calibrate_or_stop,
    check_output,
    configured_policy,
    finish,
    lens_spread,
    mdp_config,
    nominal_sensor,
    recording_kept,
    write_calibration_inputs,
    write_summary,
)
from vical.apps.entry import interrupted_by, interrupted_status, interrupts_as_raised
from vical.apps.entry import run as run_command
from vical.collection.guide import Arrival, Guide, Start
from vical.collection.page import GuidePage, PageSettings
from vical.collection.runner import CollectResult, Limits, RobotEpisode
from vical.config_checks import ConfigError, from_mapping
from vical.data import SensorTruth
from vical.env.information import Guess
from vical.env.lookahead import ReachTiming
from vical.env.reachability import check_horizon
from vical.env.settings import MdpConfig
from vical.io.atomic import replace_directory
from vical.io.euroc import EurocStreamWriter
from vical.policies.base import Policy
from vical.robot import Guidance, Person

APP = "vical-guide"
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


@dataclass(frozen=True)
class GuideSettings(CollectionOutput):
    """The checked settings of a guided collection (``check_output``'s, and the guide's own)."""

    start: Start
    arrival: Arrival
    reach: ReachTiming
    limits: Limits
    page: PageSettings


def check_settings(cfg: DictConfig) -> GuideSettings:
    """The settings of ``cfg``, checked before anything starts; ``ConfigError`` naming the key otherwise."""
    try:
        arrival = from_mapping(Arrival, plain(cfg.arrival), "arrival")
        own = {
            "start": from_mapping(Start, plain(cfg.start), "start"),
            "arrival": arrival,
            # a step ends when the guide has seen the sensor still for the arrival's window
            "reach": from_mapping(ReachTiming, {**plain(cfg.reach), "rest": arrival.still_s}, "reach"),
            "limits": from_mapping(Limits, plain(cfg.limits), "limits"),
            "page": from_mapping(PageSettings, plain(cfg.page), "page"),
        }
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return GuideSettings(**check_output(cfg), **own)


def guided_mdp(cfg: DictConfig, policy: Policy) -> MdpConfig:
    """The MDP of a guided run: ``vical-collect``'s (``mdp_config``), in which a learned policy steps in the box it
    was trained in and every other policy in the guide's (``workspace.action_scale``: a person's step)."""
    mdp = mdp_config(cfg, policy)
    return mdp if policy.action_scale is None else replace(mdp, action_scale=tuple(policy.action_scale))


class Shown(Person):
    """Every guidance shown to each of ``people`` (the page, and the simulated person who follows it)."""

    def __init__(self, people: list[Person]) -> None:
        self.people = people

    def show(self, guidance: Guidance) -> None:
        for person in self.people:
            person.show(guidance)

    def gone(self) -> str | None:
        return next((why for why in (p.gone() for p in self.people) if why is not None), None)


def guide(cfg: DictConfig) -> int:
    """Guide, record and calibrate as ``cfg`` says; the exit status (module doc)."""
    s = check_settings(cfg)
    policy = configured_policy(cfg, s.task)
    mdp = guided_mdp(cfg, policy)
    policy.check(RobotEpisode(mdp))  # before anything starts: a policy of another workspace or state
    check_horizon(s.limits.horizon_s, "limits.horizon_s", mdp.reset_hold, ReachTiming(rest=mdp.settle_time))
    holder = build_robot(cfg.person, "person")
    page = None
    try:
        try:
            nominal = nominal_sensor(s, holder)
            page = _open_page(s.page, nominal, holder, cfg)
            final, s = s.out, replace(s, out=aside(s.out))  # a collection there is replaced only by a complete one
            result = _run(cfg, s, holder, policy, mdp, nominal, page)
        finally:
            holder.close()  # the sensor is released before the calibration
        status = EXIT_FAULT if result is None else _calibrate_step(cfg, s, result, page)
        if result is not None and s.out != final:
            replace_directory(s.out, final)
            _say(page, f"the collection in {final} is replaced by this one (the paths above, under {s.out}, are "
                       "now under it)")  # fmt: skip
            s = replace(s, out=final)
        if page is not None:
            _show_result(page, s, result, status)
        return status
    finally:
        if page is not None:
            page.close()


def _open_page(settings: PageSettings, nominal: SensorTruth, holder: Any, cfg: DictConfig) -> GuidePage | None:
    """The page, serving (None when ``page.enabled`` is false); a port in use is a user error."""
    if not settings.enabled:
        return None
    try:
        page = GuidePage(nominal.camera, board(cfg, holder), settings)
    except OSError as err:
        raise ConfigError(f"page.port={settings.port}: cannot serve on {settings.host} ({err.strerror}); choose "
                          "another port (page.port=0: any free one) or page.enabled=false") from None  # fmt: skip
    print(f"{APP}: the guide's page: {page.url}", flush=True)
    return page


def _say(page: GuidePage | None, line: str) -> None:
    """A progress line, on the terminal and as the page's stage."""
    print(line, flush=True)
    if page is not None:
        page.stage(line)


def build_guide(
    cfg: DictConfig,
    s: GuideSettings,
    holder: Any,
    policy: Policy,
    mdp: MdpConfig,
    nominal: SensorTruth,
    page: GuidePage | None,
    recording: Path | None,
    progress: Callable[[str], None] | None = None,
) -> Guide:
    """The guide on ``holder``'s sensor, writing the EuRoC folder ``recording`` (None: nothing, as a comparison at
    corner level), showing the page and the simulated person; ``progress`` defaults to the page's stage and a
    printed line when ``cfg.progress``."""
    sensor = holder.sensor
    writer = None if recording is None else EurocStreamWriter(
        recording, sensor.image_size, sensor.camera_rate_hz, sensor.imu_rate_hz, nominal.imu_noise)  # fmt: skip
    guess = Guess(nominal.camera, nominal.T_cam_imu, nominal.time_offset, nominal.imu_noise,
                  mdp.information.pixel_sigma, lens_spread(cfg, mdp, nominal), nominal.imu_grade)  # fmt: skip
    people = [p for p in (page, holder) if isinstance(p, Person)]
    if progress is None:
        progress = (lambda line: _say(page, line)) if cfg.get("progress") else (lambda line: None)
    guide = Guide(sensor, Shown(people), policy, mdp, s.task, board(cfg, holder), guess, writer, s.start, s.arrival,
                  limits=s.limits, progress=progress, reach=s.reach)  # fmt: skip
    if page is not None:
        guide.stream.viewer = page.view
    return guide


def _run(cfg, s: GuideSettings, holder, policy, mdp, nominal, page) -> CollectResult | None:
    """The guided collection; None when it stopped on a fault (reported), the result otherwise."""
    write_calibration_inputs(s, board(cfg, holder), nominal, holder)
    guide_ = build_guide(cfg, s, holder, policy, mdp, nominal, page, s.out / "recording")
    writer = guide_.stream.writer
    try:
        with interrupts_as_raised():  # a lock an interrupt left half released: the interrupt
            result = guide_.run(int(cfg.seed))
    except FAULTS as err:
        with contextlib.suppress(OSError):  # a full disk (the fault, maybe) takes no summary; the line below says why
            write_summary(s, None, f"stopped: {err}", writer.frames)
        report_error(APP, f"stopped: {err}; {recording_kept(s, writer)}")
        if page is not None:
            page.finish({"outcome": f"stopped: {err}", "frames": writer.frames}, None)
        return None
    except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM (vical.apps.entry)
        write_summary(s, None, f"interrupted ({interrupted_by(err)})", writer.frames)
        print(f"{APP}: interrupted ({interrupted_by(err)}): {recording_kept(s, writer)}", file=sys.stderr)
        raise SystemExit(interrupted_status(err)) from None
    write_summary(s, result, f"done: {result.reason}", writer.frames)
    if result.out_of_reach is not None:  # the reason, whatever the progress lines: what to change, and where
        print(f"{APP}: {result.reason} (collect.yaml: out_of_reach)", file=sys.stderr)
    return result


def _calibrate_step(cfg: DictConfig, s: GuideSettings, result: CollectResult, page: GuidePage | None) -> int:
    if not cfg.get("calibrate"):
        return 0
    _say(page, f"calibrating the recording ({result.frames} frames)")
    return calibrate_or_stop(s, result, bool(cfg.get("report")))


def _show_result(page: GuidePage, s: GuideSettings, result: CollectResult | None, status: int) -> None:
    """The outcome on the page, served until its Close button or ``page.linger`` seconds (Ctrl-C ends it too: the
    work is done and written, so leaving the page early is no failure)."""
    if result is not None:
        outcome = {
            "stopped at": result.reason,
            "goal reached": result.goal_reached,
            "steps": result.steps,
            "recording [s]": round(result.duration, 1),
            "path [m]": round(result.path_length, 2),
            "frames": result.frames,
            "calibration": "done" if status == 0 else "failed (see the terminal)",
            "folder": str(s.out),
        }
        page.finish(outcome, s.out / "calibration")
    if s.page.linger > 0:
        print(f"{APP}: the result is on {page.url} for {s.page.linger:.0f} s (its Close button, or Ctrl-C, ends it "
              "now)", flush=True)  # fmt: skip
        with contextlib.suppress(KeyboardInterrupt):
            page.wait_closed(s.page.linger)


@hydra.main(config_path=CONF_DIR, config_name="guide", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    finish(APP, guide, cfg)


def main() -> None:
    """Console entry point: the settings, and Hydra's own override errors, are checked before Hydra runs."""
    check_then_run(APP, CONF_DIR, "guide", check_settings, hydra_main, USER_ERRORS)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
