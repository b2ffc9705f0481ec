"""Evaluation of a policy on a calibration task: episodes, calibrations at path budgets, table rows.

Each policy runs one episode per sensor seed (``reset(seed=s)`` draws the same sensor for every
policy, so the policies are compared on the same sensors). Every episode is calibrated at its end
by ``vical.calib.tasks.run_task``, whatever ended it (coverage, step limit, or the end of a fixed
trajectory), and at every **path budget** below its path: the recording as it stood when the end
effector had travelled that far (``Recording.until_path``), so policies are compared at equal
effort. A ``CalibrationError`` becomes a failed row; its ``prior_score_pct`` is the error of the
nominal parameters (the episode product's datasheet: the distributions' means), what a user is left with when the
calibration fails, which the paired comparisons use in its place (``vical.evaluation.error_vs_effort``).

A policy config (``conf/policy/<name>.yaml``, see :class:`PolicySpec`) holds one policy spec per
task. Under the paper's protocol (``paper_protocol``, the paper's Tables I-III) a baseline marked
``paper_two_trajectories`` runs two trajectories in the joint task, as the paper's trajectory
baselines do: its intrinsic trajectory, then its extrinsic trajectory; the two-stage solve
calibrates the intrinsics from the first recording's frames and the extrinsic from the second
recording, and the path lengths add up. Everywhere else every policy runs one trajectory.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import hydra.utils
import numpy as np
from hydra.errors import InstantiationException
from tqdm import tqdm

from vical.calib.errors import CalibrationError
from vical.calib.metrics import group_errors_px, parameter_errors
from vical.calib.tasks import CalibrationTask, TaskOutcome, run_task, task_score
from vical.config_checks import ConfigError, require
from vical.data import NS_PER_S, CameraFrames, Recording, SensorTruth
from vical.env.calibration import CalibrationEnv
from vical.env.reachability import OutOfReach, check_horizon
from vical.geometry import CameraModel
from vical.parallel import ParallelConfig, connect_ray, imap_ordered
from vical.policies.base import Policy
from vical.policies.stopping import StopRule, with_stop

SPEC_KEYS = ("intrinsic", "extrinsic", "joint")
EPISODE_FAILED = "the episode of sensor seed"  # how a failed row of an episode that raised begins
END = math.inf  # the budget of a row that calibrates the whole episode


@dataclass(frozen=True)
class PolicySpec:
    """A policy config: its table name and one ``hydra.utils.instantiate`` spec per task.

    Attributes:
        name: the table row.
        intrinsic, extrinsic, joint: specs (``_target_`` + arguments) of the policies for those tasks
            (None: the policy has none for that task).
        paper_two_trajectories: under the paper's protocol the joint task runs the intrinsic then
            the extrinsic policy (two trajectories), as the paper's trajectory baselines did.
        stop: when its episodes end (``vical.policies.stopping``; the ``stop`` group, not the policy config).
    """

    name: str
    intrinsic: Mapping[str, Any] | None
    extrinsic: Mapping[str, Any] | None
    joint: Mapping[str, Any] | None = None
    paper_two_trajectories: bool = False
    stop: StopRule = field(default_factory=StopRule)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], key: str = "policy") -> PolicySpec:
        """Read ``name``, the per-task specs and the protocol flag; other keys are parameters the specs interpolate."""
        require(isinstance(cfg, Mapping), key, "a mapping with name, intrinsic, extrinsic, joint", cfg)
        name = cfg.get("name")
        require(isinstance(name, str) and bool(name), f"{key}.name", "a non-empty string", name)
        specs = {}
        for task in SPEC_KEYS:
            spec = cfg.get(task)
            ok = spec is None or (isinstance(spec, Mapping) and "_target_" in spec)
            require(ok, f"{key}.{task}", "null or a mapping with a _target_ (a policy factory)", spec)
            specs[task] = dict(spec) if spec is not None else None
        two = cfg.get("paper_two_trajectories", cls.paper_two_trajectories)
        require(isinstance(two, bool), f"{key}.paper_two_trajectories", "true or false", two)
        return cls(name, **specs, paper_two_trajectories=two)

    def for_task(self, task: CalibrationTask, paper_protocol: bool = False) -> list[Mapping[str, Any]]:
        """The specs of the trajectories one episode of ``task`` runs (one, or two in the paper's joint task)."""
        kind = {"intrinsic": "intrinsic", "extrinsic": "extrinsic"}.get(task.calibrate, "joint")
        if kind == "joint" and paper_protocol and self.paper_two_trajectories:
            missing = [k for k in ("intrinsic", "extrinsic") if getattr(self, k) is None]
            if missing:
                raise ConfigError(f"policy {self.name!r} runs two trajectories but has no {' / '.join(missing)} spec")
            return [self.intrinsic, self.extrinsic]
        spec = getattr(self, kind)
        if spec is None:
            only_paper = " (it runs two trajectories under the paper's protocol: paper_protocol=true)"
            raise ConfigError(
                f"policy {self.name!r} has no spec for the {kind} task (its `{kind}` key is null)"
                + (only_paper if kind == "joint" and self.paper_two_trajectories else "")
            )
        return [spec]


def instantiate_policy(spec: Mapping[str, Any], name: str) -> Policy:
    """Build a policy from its spec; ``ConfigError`` (one line) when the factory fails or returns no Policy."""
    try:
        policy = hydra.utils.instantiate(dict(spec))
    except InstantiationException as err:
        if isinstance(err.__cause__, ConfigError | FileNotFoundError):
            raise ConfigError(f"policy {name!r}: {err.__cause__}") from err
        cause = err.__cause__ if err.__cause__ is not None else err
        raise ConfigError(f"policy {name!r}: {spec.get('_target_')} failed: {cause}") from err
    if not isinstance(policy, Policy):
        raise ConfigError(f"policy {name!r}: {spec.get('_target_')} returned {type(policy).__name__}, not a Policy")
    return policy


# The columns that measure this machine's wall time, not the episode: they differ between runs of one episode.
WALL_TIME_FIELDS = ("calib_time_s", "decision_ms")


@dataclass
class EpisodeRow:
    """One evaluated sensor at one path budget (None where the task estimates no such quantity or it failed).

    Attributes:
        policy: the table row it belongs to.
        seed: the env reset seed (the sensor).
        budget_m: the path budget [m] the recording was cut at; ``inf`` for the whole episode.
        score_pct: the task's error [%] (the paper's tables).
        intrinsic_pct, extrinsic_pct: relative errors [%].
        intrinsic_px: ``||[fx, fy, cx, cy] - gt||`` [px].
        focal_px, principal_point_px, distortion_px: the intrinsic groups' errors [px] as the information
            state's tolerances measure them (``vical.calib.metrics.group_errors_px``).
        rotation_deg, translation_mm: extrinsic ``T_cam_imu`` errors [deg], [mm].
        time_offset_ms: |time offset error| [ms].
        prior_score_pct: the task's error [%] of the nominal parameters (its product's datasheet):
            what a failed calibration leaves.
        path_length_m: executed end-effector path [m] of the calibrated data (both trajectories in
            two-trajectory mode).
        recording_time_s: time [s] from the recording's start to its (cut) end.
        calib_time_s: calibrator wall time [s] (until the failure for a failed calibration).
        steps: env steps of the episode (both trajectories).
        frames: camera frames the calibration was given.
        decision_ms: the policy's mean time [ms] to choose an action (its ``act``), per step of the episode.
        coverage_reached: every trajectory of the episode reached the MDP's terminal condition (the
            coverage; for a policy of the information state: every parameter group within tolerance).
        out_of_reach: the group the reachability forecast called out of reach within the horizon ("" none;
            ``stop.out_of_reach``), at ``verdict_s`` [s] of recording: the run stopped there (its recording is
            calibrated up to it).
        predicted_s: the goal's recording time [s] the forecast predicted halfway to it (``halfway_forecast``).
        reached_s: when the goal was met [s]: at the stop, or (``stop.verify_s``) after an out-of-reach verdict, the
            run going on to check it; None: not within the run.
        short_at_horizon: the goal's groups a run that did not meet it by the horizon (or its verdict) lacked, with
            their predicted error over tolerance at the horizon (the forecast's, at the verdict): ``"time_offset 1.64
            rotation 1.37"``; "" for a run that met it.
        failed: the calibration raised ``CalibrationError``; ``error`` holds its message.
    """

    policy: str
    seed: int
    budget_m: float = END
    score_pct: float | None = None
    intrinsic_pct: float | None = None
    extrinsic_pct: float | None = None
    intrinsic_px: float | None = None
    focal_px: float | None = None
    principal_point_px: float | None = None
    distortion_px: float | None = None
    rotation_deg: float | None = None
    translation_mm: float | None = None
    time_offset_ms: float | None = None
    prior_score_pct: float | None = None
    path_length_m: float = 0.0
    recording_time_s: float = 0.0
    calib_time_s: float = 0.0
    steps: int = 0
    frames: int = 0
    decision_ms: float | None = None
    coverage_reached: bool = False
    out_of_reach: str = ""
    verdict_s: float | None = None
    predicted_s: float | None = None
    reached_s: float | None = None
    short_at_horizon: str = ""
    failed: bool = False
    error: str = ""

    @property
    def effective_score_pct(self) -> float:
        """The score, or the nominal parameters' score for a failed calibration (paired comparisons)."""
        if not self.failed and self.score_pct is not None:
            return float(self.score_pct)
        return math.nan if self.prior_score_pct is None else float(self.prior_score_pct)


COLUMNS = tuple(f.name for f in dataclasses.fields(EpisodeRow))


@dataclass(frozen=True)
class Summary:
    """The paper's table columns for one policy, over its successful episodes (errors) or all (path, time).

    Attributes:
        policy: the table row.
        episodes: episodes run; failed: calibrations that raised ``CalibrationError``.
        mean_error_pct, error_std_pct: mean and population std of the task score [%] (NaN if none succeeded).
        path_length_m: mean path length [m]; calib_time_s: mean calibrator wall time [s].
        intrinsic_px, rotation_deg, translation_mm, time_offset_ms: mean absolute errors (None if not estimated).
        coverage_rate: fraction of episodes whose coverage was complete.
    """

    policy: str
    episodes: int
    failed: int
    mean_error_pct: float
    error_std_pct: float
    path_length_m: float
    calib_time_s: float
    intrinsic_px: float | None
    rotation_deg: float | None
    translation_mm: float | None
    time_offset_ms: float | None
    coverage_rate: float


@dataclass(frozen=True)
class Evaluation:
    """Per-episode rows (every budget) and the paper-table summary (whole episodes) of one policy on one task."""

    rows: list[EpisodeRow]
    summary: Summary


@dataclass(frozen=True)
class Trajectory:
    """One executed trajectory: its recording, the steps taken, whether the coverage completed and the policy's
    total time choosing its actions [s]; with the reachability verdict (``run_trajectory``), the verdict, the goal's
    recording time [s] the forecast predicted halfway to it (``halfway_forecast``), when the goal was met [s] (past
    the verdict too) and, for a run that did not meet it by the verdict or the horizon, each goal group above its
    tolerance with its ratio at the horizon (``short``)."""

    recording: Recording
    steps: int
    coverage_reached: bool
    decision_s: float = 0.0
    out_of_reach: OutOfReach | None = None
    predicted_s: float | None = None
    reached_s: float | None = None
    short: dict[str, float] = field(default_factory=dict)

    @property
    def used(self) -> Recording:
        """The recording the run ends with: all of it, or up to the verdict of a run stopped as out of reach."""
        if self.out_of_reach is None:
            return self.recording
        return self.recording.until(self.recording.t0 + int(self.out_of_reach.at_s * NS_PER_S))


def policy_mdp(policy: Policy) -> dict[str, Any]:
    """What ``policy``'s episodes change of an env config: its MDP settings, step limit and termination.

    The env never calibrates on its own: the evaluation calibrates every episode once per budget,
    ``vical-collect`` once at the end.
    """
    settings = {
        **dict(policy.env_settings),
        "terminate_on_coverage": policy.stop_at_coverage,
        "calibrate_on_termination": False,
        "calibrate_on_truncation": False,
    }
    if policy.max_steps is not None:
        settings["max_steps"] = policy.max_steps
    return settings


def build_env(env_cfg: Mapping[str, Any], policy: Policy) -> CalibrationEnv:
    """The calibration env of ``env_cfg`` with ``policy``'s MDP settings, step limit and termination."""
    try:
        env = hydra.utils.instantiate({**dict(env_cfg), **policy_mdp(policy)})
    except InstantiationException as err:
        if isinstance(err.__cause__, ConfigError):  # a bad setting of the sensor, sim, task or MDP: its own line
            raise err.__cause__ from None
        raise
    if not isinstance(env, CalibrationEnv):
        raise ConfigError(f"env must be the calibration env (env=calibration), got {type(env).__name__}")
    return env


def run_trajectory(
    env: CalibrationEnv,
    policy: Policy,
    seed: int,
    noise_stream: int = 0,
    horizon_s: float | None = None,
    out_of_reach: bool = False,
    verify_s: float | None = None,
) -> Trajectory:
    """One episode of ``policy`` on the sensor of ``seed``: until termination, truncation or the policy is done,
    or, with ``horizon_s``, the first step that ends at or past that much simulated time [s] (the time-to-tolerance
    summary counts a run not stopped by its horizon at it: what it would record after is never used), or, with
    ``out_of_reach`` (the information state), the step at which its reachability forecast calls the goal out of
    reach within the horizon (``vical.env.reachability``). With ``verify_s`` a run called out of reach goes on to
    that much time, to see whether it reaches the goal after all (its recording is used up to the verdict).

    ``noise_stream`` selects the sensor noise of the recording (another trajectory of the same sensor
    records other noise).
    """
    obs, _ = env.reset(seed=seed, options={"noise_stream": noise_stream})
    policy.reset(env, np.random.default_rng(seed))
    deciding, verdict, reached, forecasts, verdict_groups = 0.0, None, None, [], {}
    reach = env.state.reach if out_of_reach and horizon_s is not None else None
    for _ in range(env.config.max_steps):
        start = time.perf_counter()
        action = policy.act(obs, env)
        deciding += time.perf_counter() - start
        if policy.finished:  # a fixed trajectory past its last waypoint: nothing left to record
            break
        obs, _, terminated, truncated, _ = env.step(action)
        time_s = env.sim.time_ns / NS_PER_S
        if terminated:
            reached = time_s
            break
        if reach is None:
            limit = horizon_s
        else:
            forecasts.append((reach.time_s, reach.needed_s()))
            if verdict is None and (verdict := reach.verdict(horizon_s)) is not None:
                verdict_groups = reach.groups(horizon_s)  # the forecast the verdict was made on
                if verify_s is None:
                    break
            limit = horizon_s if verdict is None else verify_s
        if truncated or (limit is not None and time_s >= limit):
            break
    predicted = halfway_forecast(forecasts, reached) if verdict is None else None
    short = {}
    if reach is not None and (verdict is not None or reached is None):  # what it lacked, as of its end
        at_horizon = verdict_groups if verdict is not None else reach.groups(horizon_s)
        short = {g: f.ratio_at_horizon for g, f in at_horizon.items() if f.ratio_at_horizon > 1.0}
    return Trajectory(env.recording(), env.steps, env.goal_reached and verdict is None, deciding, verdict,
                      predicted, reached, short)  # fmt: skip


def halfway_forecast(forecasts: Sequence[tuple[float, float]], reached_s: float | None) -> float | None:
    """The goal's predicted recording time [s] when half the time a run took to reach it was in (``forecasts``: the
    forecast's time and prediction after each step): what the forecast told a user halfway; None without a goal
    reached, or an infinite prediction."""
    if reached_s is None:
        return None
    halfway = next((needed for t, needed in forecasts if t >= reached_s / 2), None)
    return halfway if halfway is not None and math.isfinite(halfway) else None


def _optional(value: float | None) -> float | None:
    return None if value is None else float(value)


def fill_outcome(row: EpisodeRow, outcome: TaskOutcome, truth_camera: CameraModel) -> None:
    """Fill ``row``'s errors from a task's calibration ``outcome`` against the sensor's true camera."""
    e = outcome.errors
    row.score_pct = float(outcome.score)
    row.intrinsic_pct = float(e.intrinsic_pct)
    row.intrinsic_px = float(np.linalg.norm(e.intrinsic_abs_px))
    groups = group_errors_px(outcome.result.camera, truth_camera)
    row.focal_px, row.principal_point_px = groups["focal"], groups["principal_point"]
    row.distortion_px = groups["distortion"]
    row.extrinsic_pct = _optional(e.extrinsic_pct)
    row.rotation_deg = _optional(e.rotation_deg)
    row.translation_mm = _optional(e.translation_mm)
    row.time_offset_ms = _optional(e.time_offset_ms)
    row.calib_time_s = float(outcome.result.solve_time)


def calibrate_row(
    row: EpisodeRow, task: CalibrationTask, recording: Recording, intrinsic_frames: CameraFrames | None = None
) -> EpisodeRow:
    """Calibrate ``recording`` as ``task`` says and fill ``row``'s errors; a ``CalibrationError`` marks it failed."""
    row.frames = len(recording.frames) + (0 if intrinsic_frames is None else len(intrinsic_frames))
    start = time.perf_counter()
    try:
        outcome = run_task(task, recording, intrinsic_frames)
    except CalibrationError as err:
        row.failed, row.error, row.calib_time_s = True, str(err), time.perf_counter() - start
        return row
    fill_outcome(row, outcome, recording.truth.camera)
    return row


def prior_score(task: CalibrationTask, nominal: SensorTruth, truth: SensorTruth) -> float:
    """The task's score [%] of the nominal parameters ``nominal`` against ``truth`` (no calibration at all)."""
    needs_extrinsic = task.error_metric == "extrinsic_relative"
    T = nominal.T_cam_imu if needs_extrinsic else None
    return task_score(task, parameter_errors(nominal.camera, T, nominal.time_offset, truth))


def check_budgets(budgets: Sequence[float]) -> tuple[float, ...]:
    """Path budgets [m]: finite, positive and strictly increasing; ``ConfigError`` naming ``budgets`` otherwise."""
    try:
        values = tuple(float(b) for b in budgets)
    except (TypeError, ValueError):
        raise ConfigError(f"budgets must be a list of path lengths [m], got {budgets!r}") from None
    ok = all(math.isfinite(b) and b > 0 for b in values) and all(b < c for b, c in itertools.pairwise(values))
    require(
        ok, "budgets", "strictly increasing path lengths > 0 [m] (the whole episode is always added)", list(budgets)
    )
    return values


class PolicyEvaluator:
    """Runs one policy spec on one task: builds its policies and envs once, then one episode per seed.

    Args:
        spec: the policy config.
        env_cfg: the calibration env config (``_target_``, ``sim``, ``sensor``, ``task`` and the MDP), resolved.
        budgets: path budgets [m] at which every episode is also calibrated (``check_budgets``).
        paper_protocol: the paper's protocol (two trajectories for the marked baselines in the joint task).

    Raises:
        ConfigError: a policy cannot run in this env (``Policy.check``), or budgets were asked for a
            two-trajectory episode (a path budget has no meaning across two recordings).
    """

    def __init__(
        self,
        spec: PolicySpec,
        env_cfg: Mapping[str, Any],
        budgets: Sequence[float] = (),
        paper_protocol: bool = False,
    ) -> None:
        self.spec = spec
        information = spec.stop.rule == "information"
        self.horizon_s = spec.stop.horizon_s if information else None
        self.out_of_reach = information and spec.stop.out_of_reach
        self.verify_s = spec.stop.verify_s if self.out_of_reach else None
        self.task = CalibrationTask.from_config(env_cfg["task"])
        self.budgets = check_budgets(budgets)
        self.paper_protocol = paper_protocol
        self.policies = [
            with_stop(instantiate_policy(s, spec.name), spec.stop) for s in spec.for_task(self.task, paper_protocol)
        ]
        self.envs = [build_env(env_cfg, p) for p in self.policies]
        for policy, env in zip(self.policies, self.envs, strict=True):
            policy.check(env)
            check_horizon(self.horizon_s, "stop.horizon_s", env.config.reset_hold, env.step_timing)
        if len(self.policies) == 2:  # the paper's baselines: intrinsics from the first trajectory's frames
            if self.budgets:
                raise ConfigError(
                    f"policy {spec.name!r} runs two trajectories (paper_protocol=true): path budgets apply to one "
                    "recording; pass budgets=[]"
                )
            self.task = dataclasses.replace(self.task, calibrate="two_stage")

    def episode(self, seed: int) -> list[EpisodeRow]:
        """Run the trajectory (or both) on the sensor of ``seed`` and calibrate it at every budget and whole.

        Returns one row per budget below the episode's path, then the whole episode's row (``budget_m = inf``).
        """
        pairs = zip(self.envs, self.policies, strict=True)
        runs = [run_trajectory(env, p, seed, k, self.horizon_s, self.out_of_reach, self.verify_s)
                for k, (env, p) in enumerate(pairs)]  # fmt: skip
        recording = runs[-1].used
        verdict = runs[-1].out_of_reach
        common = {
            "policy": self.spec.name,
            "seed": seed,
            "steps": sum(r.steps for r in runs),
            "coverage_reached": all(r.coverage_reached for r in runs),
            "out_of_reach": "" if verdict is None else verdict.group,
            "verdict_s": None if verdict is None else verdict.at_s,
            "predicted_s": runs[-1].predicted_s,
            "reached_s": runs[-1].reached_s,
            "short_at_horizon": " ".join(f"{g} {r:.3g}" for g, r in runs[-1].short.items()),
            "decision_ms": 1e3 * sum(r.decision_s for r in runs) / max(sum(r.steps for r in runs), 1),
            "prior_score_pct": prior_score(self.task, self.envs[-1].product.datasheet, recording.truth),
        }
        if len(runs) == 2:
            row = EpisodeRow(**common, path_length_m=float(sum(r.recording.path_length for r in runs)))
            row.recording_time_s = float(sum(r.recording.duration for r in runs))
            return [calibrate_row(row, self.task, recording, runs[0].recording.frames)]
        total = recording.path_length
        cuts = [(b, recording.until_path(b)) for b in self.budgets if b < total] + [(END, recording)]
        return [self._budget_row(common, budget, cut) for budget, cut in cuts]

    def _budget_row(self, common: dict[str, Any], budget: float, recording: Recording) -> EpisodeRow:
        row = EpisodeRow(**common, budget_m=budget, path_length_m=float(recording.path_length))
        row.recording_time_s = (recording.t_end - recording.t0) / 1e9
        return calibrate_row(row, self.task, recording)

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _mean(rows: Sequence[EpisodeRow], key: str) -> float | None:
    values = [getattr(r, key) for r in rows if getattr(r, key) is not None]
    return float(np.mean(values)) if values else None


def summarize(name: str, rows: Sequence[EpisodeRow]) -> Summary:
    """The paper's table columns of whole-episode ``rows``: errors over successful rows, path and time over all."""
    rows = [r for r in rows if r.budget_m == END]
    ok = [r for r in rows if not r.failed]
    scores = np.array([r.score_pct for r in ok], dtype=float)
    return Summary(
        policy=name,
        episodes=len(rows),
        failed=len(rows) - len(ok),
        mean_error_pct=float(scores.mean()) if len(scores) else math.nan,
        error_std_pct=float(scores.std()) if len(scores) else math.nan,
        path_length_m=float(np.mean([r.path_length_m for r in rows])) if rows else math.nan,
        calib_time_s=float(np.mean([r.calib_time_s for r in rows])) if rows else math.nan,
        intrinsic_px=_mean(ok, "intrinsic_px"),
        rotation_deg=_mean(ok, "rotation_deg"),
        translation_mm=_mean(ok, "translation_mm"),
        time_offset_ms=_mean(ok, "time_offset_ms"),
        coverage_rate=float(np.mean([r.coverage_reached for r in rows])) if rows else math.nan,
    )


@dataclass(frozen=True)
class EpisodeTask:
    """One episode to evaluate, self-contained so that any worker process can run it (picklable).

    Attributes:
        spec: the policy; env_cfg: the resolved calibration env config; budgets: path budgets [m];
        paper_protocol: the paper's protocol; seed: the env reset seed (the sensor).
    """

    spec: PolicySpec
    env_cfg: Mapping[str, Any]
    budgets: tuple[float, ...]
    paper_protocol: bool
    seed: int

    @property
    def evaluator_key(self) -> str:
        """What a worker's cached evaluator must match to run this episode."""
        parts = [dataclasses.asdict(self.spec), self.env_cfg, self.budgets, self.paper_protocol]
        return json.dumps(parts, sort_keys=True, default=str)


# Per process: evaluators built once (their env compiles a MuJoCo model, the policy may load a network)
# and reused for every episode of the same policy that this process runs.
_EVALUATORS: dict[str, PolicyEvaluator] = {}


def run_episode(task: EpisodeTask) -> list[EpisodeRow]:
    """Evaluate one episode (in whatever process runs it); an unexpected error becomes a failed row naming the seed.

    A ``CalibrationError`` already yields a failed row (``calibrate_row``); anything else that goes wrong
    in the episode (the simulator, the policy) is reported the same way instead of ending the whole
    evaluation.
    """
    evaluator = _EVALUATORS.get(task.evaluator_key)
    if evaluator is None:
        evaluator = _EVALUATORS[task.evaluator_key] = PolicyEvaluator(
            task.spec, task.env_cfg, task.budgets, task.paper_protocol
        )
    try:
        return evaluator.episode(task.seed)
    except Exception as err:  # reported in the results; the evaluation goes on
        message = f"{EPISODE_FAILED} {task.seed} failed: {type(err).__name__}: {err}"
        return [EpisodeRow(task.spec.name, task.seed, failed=True, error=message)]


def adopt(evaluator: PolicyEvaluator, env_cfg: Mapping[str, Any]) -> None:
    """Let ``run_episode`` in this process use an evaluator built here already (a serial run builds it once)."""
    task = EpisodeTask(evaluator.spec, env_cfg, evaluator.budgets, evaluator.paper_protocol, 0)
    _EVALUATORS[task.evaluator_key] = evaluator


def release_evaluators() -> None:
    """Close and forget this process's cached evaluators (their envs hold simulators and renderers)."""
    while _EVALUATORS:
        _EVALUATORS.popitem()[1].close()


def evaluate_policies(
    specs: Sequence[PolicySpec],
    env_cfg: Mapping[str, Any],
    seeds: Sequence[int],
    budgets: Sequence[float] = (),
    paper_protocol: bool = False,
    parallel: ParallelConfig | None = None,
    progress: bool = True,
) -> list[Evaluation]:
    """Every policy on every sensor seed, the episodes spread over ``parallel``'s workers.

    Every policy is built here first, so that a bad spec fails in seconds, not after hours of episodes.
    The rows come back in (policy, seed) order whatever ran them: a parallel evaluation is the serial
    one, only faster.
    """
    if not seeds:
        raise ConfigError("episodes must be at least 1 (no seeds to evaluate)")
    parallel = parallel or ParallelConfig()
    budgets = check_budgets(budgets)
    if parallel.backend == "ray":
        connect_ray(parallel)  # an unreachable cluster fails now, not after the policies are built
    evaluators = [PolicyEvaluator(spec, env_cfg, budgets, paper_protocol) for spec in specs]
    try:
        if parallel.serial:
            for evaluator in evaluators:
                adopt(evaluator, env_cfg)
        else:
            for evaluator in evaluators:
                evaluator.close()
        tasks = [EpisodeTask(spec, env_cfg, budgets, paper_protocol, int(seed)) for spec in specs for seed in seeds]
        bar = tqdm(total=len(tasks), desc="episodes", unit="episode", disable=not progress)
        rows: dict[str, list[EpisodeRow]] = {spec.name: [] for spec in specs}
        # closed on the way out, an interrupt's too: the workers end now, not when the traceback is released
        with contextlib.closing(imap_ordered(run_episode, tasks, parallel)) as results:
            for task, episode_rows in zip(tasks, results, strict=True):
                rows[task.spec.name].extend(episode_rows)
                bar.set_postfix_str(f"{task.spec.name}, sensor {task.seed}")
                bar.update(1)
        bar.close()
    finally:
        release_evaluators()
    return [Evaluation(rows[spec.name], summarize(spec.name, rows[spec.name])) for spec in specs]


def evaluate_policy(
    spec: PolicySpec,
    env_cfg: Mapping[str, Any],
    seeds: Sequence[int],
    progress: bool = True,
    budgets: Sequence[float] = (),
    paper_protocol: bool = False,
) -> Evaluation:
    """Evaluate ``spec`` on the task of ``env_cfg`` for every sensor seed (in this process); rows and the summary."""
    return evaluate_policies([spec], env_cfg, seeds, budgets, paper_protocol, progress=progress)[0]
