"""Each default has one home: every key of a conf/ file that a dataclass (or a constructor) reads equals its default.

The files state their settings, so the composed configs (and a run's config.yaml) show the values the command
line runs with; the dataclasses (``MdpConfig``, ``SensorSampling``, ``SACConfig``, ...) hold the same values as
their defaults, for Python callers that build them without a config, and fill in a key that a file leaves out.
This test reads each file as written (before Hydra merges anything) and compares every key, recursively, with the
default of the field or argument it sets; a failure names the key, the YAML's value and the code's. Three kinds
of keys are not compared, each by an explicit rule below: interpolations (``${workspace.action_scale}``: the
value is stated in the group they name, which is compared there), Hydra's own keys (``defaults``, ``_target_``)
and the keys of ``DIFFERS``: settings a file changes on purpose (a mode, an option of a group), each with its
reason. ``NO_COUNTERPART`` names the files (and parts of files) that nothing with a default reads.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import MISSING, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from vical.calib.tasks import CalibrationTask
from vical.collection.guide import Arrival, Start
from vical.collection.page import PageSettings
from vical.collection.runner import Alignment, Limits
from vical.env.lookahead import ReachTiming
from vical.env.settings import MdpConfig, Workspace
from vical.evaluation.harness import PolicySpec
from vical.parallel import ParallelConfig
from vical.policies.greedy import greedy_information_policy
from vical.policies.learned import learned_policy
from vical.policies.stopping import StopRule
from vical.policies.two_step import two_step_planner_policy
from vical.rl.run_settings import TrainConfig
from vical.rl.sac import SACConfig
from vical.robot.franka import FrankaArm
from vical.robot.realsense import RealSenseSensor
from vical.robot.rigs import ros, ros_in_hand
from vical.robot.ros import RosArm, RosSensor
from vical.robot.ur import URArm
from vical.sim.adapters import RigFaults
from vical.sim.hand_held import hand_held_rig
from vical.sim.person import HandModel
from vical.sim.sampling import SensorSampling
from vical.sim.settings import SimConfig

CONF = Path(__file__).resolve().parents[1] / "conf"
NO_DEFAULT = object()  # a field or argument without a default: the YAML is the only place that states it
HYDRA_KEYS = ("defaults", "_target_")  # Hydra's defaults list and the factory a node instantiates


def dataclass_defaults(cls: type, **extra: Any) -> dict[str, Any]:
    """The default of every field of ``cls`` (nested dataclasses as mappings), plus ``extra``."""
    out = {}
    for f in fields(cls):
        if f.default is not MISSING:
            out[f.name] = _plain(f.default)
        elif f.default_factory is not MISSING:
            out[f.name] = _plain(f.default_factory())
        else:
            out[f.name] = NO_DEFAULT
    return {**out, **extra}


def argument_defaults(function: Callable, **extra: Any) -> dict[str, Any]:
    """The default of every argument of ``function`` (a class: of its ``__init__``), plus ``extra``."""
    parameters = inspect.signature(function).parameters.values()
    return {
        **{p.name: NO_DEFAULT if p.default is p.empty else _plain(p.default) for p in parameters if p.name != "self"},
        **extra,
    }


def _plain(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


# What each file's nodes set: (file under conf/, path of the node in the file, the defaults of what reads it).
# The workspace files are `# @package _global_`: their `sim` node sets SimConfig's board, start and IK, their
# `workspace` node the env's Workspace and action scale (conf/env/calibration.yaml interpolates them).
WORKSPACE = dataclass_defaults(Workspace, action_scale=_plain(MdpConfig.action_scale))
# A policy file: PolicySpec's name, per-task factory specs and protocol flag, and the parameters the specs
# interpolate (the learned policy's and the planner's run directory: learned_policy's argument; the workspace's
# name; the planner's random candidates: greedy_information_policy's argument, the rate planner's in the intrinsic
# task only in its file; the two-step planner's branches: two_step_planner_policy's argument). The specs
# are what each policy is, no settings with a default (PolicySpec's joint=None: a policy without a joint spec).
POLICY = dataclass_defaults(
    PolicySpec,
    joint=NO_DEFAULT,
    run_dir=argument_defaults(learned_policy)["run_dir"],
    workspace=NO_DEFAULT,
    samples=argument_defaults(greedy_information_policy)["samples"],
    intrinsic_samples=NO_DEFAULT,
    branches=argument_defaults(two_step_planner_policy)["branches"],
)
IDENTITY = np.eye(4).tolist()  # T_flange_tool=None (the robot adapters' default) is the identity the YAML writes
PAIRS: list[tuple[str, tuple[str, ...], dict[str, Any]]] = [
    ("sim/default.yaml", (), dataclass_defaults(SimConfig)),
    ("sensor/paper.yaml", (), dataclass_defaults(SensorSampling)),
    ("sensor/stereo.yaml", (), dataclass_defaults(SensorSampling)),
    ("sensor/practitioner.yaml", (), dataclass_defaults(SensorSampling)),
    ("sensor/practitioner_graded.yaml", (), dataclass_defaults(SensorSampling)),
    ("sensor/rolling_shutter.yaml", (), dataclass_defaults(SensorSampling)),
    ("task/intrinsic.yaml", (), dataclass_defaults(CalibrationTask)),
    ("task/extrinsic.yaml", (), dataclass_defaults(CalibrationTask)),
    ("task/joint.yaml", (), dataclass_defaults(CalibrationTask)),
    ("env/calibration.yaml", (), dataclass_defaults(MdpConfig)),
    ("env/information.yaml", (), dataclass_defaults(MdpConfig)),
    ("agent/sac.yaml", (), dataclass_defaults(SACConfig)),
    ("agent/sac_authors.yaml", (), dataclass_defaults(SACConfig)),
    ("parallel/local.yaml", (), dataclass_defaults(ParallelConfig)),
    ("parallel/ray.yaml", (), dataclass_defaults(ParallelConfig)),
    ("workspace/paper.yaml", ("sim",), dataclass_defaults(SimConfig)),
    ("workspace/paper.yaml", ("workspace",), WORKSPACE),
    ("workspace/practitioner.yaml", ("sim",), dataclass_defaults(SimConfig)),
    ("workspace/practitioner.yaml", ("workspace",), WORKSPACE),
    ("train.yaml", ("train",), dataclass_defaults(TrainConfig)),
    ("collect.yaml", ("align",), dataclass_defaults(Alignment)),
    ("collect.yaml", ("limits",), dataclass_defaults(Limits)),
    ("robot/sim.yaml", ("faults",), dataclass_defaults(RigFaults)),
    ("stop/policy.yaml", (), dataclass_defaults(StopRule)),
    ("stop/information.yaml", (), dataclass_defaults(StopRule)),
    *((f"policy/{path.name}", (), POLICY) for path in sorted((CONF / "policy").glob("*.yaml"))),
    ("robot/franka.yaml", ("arm",), argument_defaults(FrankaArm, T_flange_tool=IDENTITY)),
    ("robot/franka.yaml", ("sensor",), argument_defaults(RealSenseSensor)),
    ("robot/ur.yaml", ("arm",), argument_defaults(URArm, T_flange_tool=IDENTITY)),
    ("robot/ur.yaml", ("sensor",), argument_defaults(RealSenseSensor)),
    ("robot/ros.yaml", (), argument_defaults(ros)),
    ("robot/ros.yaml", ("arm",), argument_defaults(RosArm, T_flange_tool=IDENTITY)),
    ("robot/ros.yaml", ("sensor",), argument_defaults(RosSensor)),
    ("guide.yaml", ("start",), dataclass_defaults(Start)),
    ("guide.yaml", ("arrival",), dataclass_defaults(Arrival)),
    ("guide.yaml", ("reach",), dataclass_defaults(ReachTiming)),
    ("guide.yaml", ("limits",), dataclass_defaults(Limits)),
    ("guide.yaml", ("page",), dataclass_defaults(PageSettings)),
    ("person/sim.yaml", (), {**argument_defaults(hand_held_rig), **dataclass_defaults(HandModel)}),
    ("person/realsense.yaml", ("sensor",), argument_defaults(RealSenseSensor)),
    ("person/ros.yaml", (), argument_defaults(ros_in_hand)),
    ("person/ros.yaml", ("sensor",), argument_defaults(RosSensor)),
]

# Files whose keys no dataclass or constructor default reads, so they are the only home of their values.
NO_COUNTERPART = {
    "collect.yaml": "the app's own settings (read by vical.apps.collect) besides `align` and `limits` (PAIRS)",
    "evaluate.yaml": "the app's own settings, read by vical.apps.evaluate; no dataclass holds defaults of them",
    "guide.yaml": "the app's own settings (vical.apps.guide's) besides start, arrival, reach, limits, page (PAIRS)",
    "record.yaml": "the app's own settings, checked by vical.apps.record.check_settings (no defaults)",
    "train.yaml": "seed, torch_threads, run_dir, resume: RunSettings has no defaults; `train` is in PAIRS",
    "env/pendulum.yaml": "gymnasium.make's arguments (the env id)",
    "hydra/job_logging/run_log.yaml": "Python logging's dictConfig for vical-train, read by Hydra: no vical defaults",
    "robot/sim.yaml": "sim, sensor, seed and asymmetric_distortion interpolate the root config; `faults` is in PAIRS",
    "experiment/": "experiments override the groups' settings on purpose: they are what differs, not defaults",
    "hydra/launcher/": "the launcher plugins' settings",
}

# Settings a file changes on purpose: (file, dotted key) -> why. Everything else must equal its default.
PRACTITIONER = "the practitioner's workspace (docs/workspace.md); the dataclasses' defaults are the authors' (paper)"
DIFFERS = {
    ("sensor/stereo.yaml", "rig"): "a stereo rig is the point of this file (its other camera); the default has none",
    ("sensor/practitioner.yaml", "time_offset.std"): "a practitioner's camera and IMU are not synchronised",
    ("sensor/practitioner.yaml", "products"): "the products drawn per episode are the point of this file",
    ("sensor/practitioner_graded.yaml", "products"): "its IMUs' grades are the point of this file",
    ("sensor/rolling_shutter.yaml", "camera.line_delay.mean"): "a rolling shutter is the point of this file",
    ("sensor/rolling_shutter.yaml", "camera.line_delay.std"): "its line delay drawn per episode",
    ("sensor/rolling_shutter.yaml", "camera.rate_hz"): "20 Hz, as the rolling-shutter cameras it stands for",
    # The information MDP: conf/env/information.yaml composes from conf/env/calibration.yaml (MdpConfig's defaults,
    # the paper's coverage MDP) and changes the mode, its step limit and its reward.
    ("env/information.yaml", "state"): "the information mode is the point of this file",
    ("env/information.yaml", "max_steps"): "the information MDP's step limit (random motion is done after ~25)",
    ("env/information.yaml", "calibrate_on_termination"): "its reward needs no solve",
    ("env/information.yaml", "reward.path_weight"): "the information MDP's path charge (docs/env.md)",
    # The authors' agent settings, one option of the agent group (docs/rl.md compares them with sac.yaml's).
    ("agent/sac_authors.yaml", "gamma"): "the authors' code's setting",
    ("agent/sac_authors.yaml", "tau"): "the authors' code's setting",
    ("agent/sac_authors.yaml", "batch_size"): "the authors' code's setting",
    ("agent/sac_authors.yaml", "n_q"): "the authors' code's setting",
    ("agent/sac_authors.yaml", "alpha"): "the authors' code's setting",
    ("stop/information.yaml", "rule"): "the information state's rule for every baseline is the point of this option",
    ("guide.yaml", "limits.time_limit"): "a guided person's limit is seconds of recording (the arm's 900 s are wall "
    "time, alignment and all)",
    ("person/realsense.yaml", "sensor.exposure_us"): "a sensor in a hand moves: a short fixed exposure against blur",
    # A Ray cluster instead of local processes.
    ("parallel/ray.yaml", "workers"): "a cluster runs more than one worker",
    ("parallel/ray.yaml", "backend"): "the point of this option",
    ("parallel/ray.yaml", "ray_address"): "the cluster this node belongs to",
    # The three tasks: CalibrationTask's defaults are the joint task (conf/task/joint.yaml).
    ("task/intrinsic.yaml", "name"): "another task",
    ("task/intrinsic.yaml", "calibrate"): "another task",
    ("task/intrinsic.yaml", "error_metric"): "another task",
    ("task/intrinsic.yaml", "asymmetric_distortion"): "the paper's intrinsic task has a centred lens",
    ("task/extrinsic.yaml", "name"): "another task",
    ("task/extrinsic.yaml", "calibrate"): "another task",
    ("task/extrinsic.yaml", "asymmetric_distortion"): "the paper's extrinsic task has a centred lens",
    # The authors' workspace is the dataclasses' default but for the IK restarts of the paper's measurements.
    ("workspace/paper.yaml", "sim.ik.restart_spread"): "IK restarts uniform over the joint ranges, as the paper's "
    "tables were measured (sim/default.yaml keeps the arm on its branch)",
    **{
        ("workspace/practitioner.yaml", key): PRACTITIONER
        for key in (
            *("sim.start", "sim.board.kind", "sim.board.cols", "sim.board.square", "sim.board.distance"),
            *("workspace.name", "workspace.frame", "workspace.position", "workspace.orientation"),
            "workspace.action_scale",
        )
    },
    # The trajectory baselines that the paper ran twice in the joint task (PolicySpec's default: one trajectory).
    **{
        (f"policy/{name}.yaml", "paper_two_trajectories"): "the paper's protocol runs its intrinsic, then its "
        "extrinsic trajectory in the joint task"
        for name in ("handcrafted_long", "handcrafted_short", "model_based", "random_trajectory")
    },
}


def _is_interpolation(value: Any) -> bool:
    return isinstance(value, str) and "${" in value


def _same(value: Any, default: Any) -> bool:
    if isinstance(value, Mapping) and isinstance(default, Mapping):
        return set(value) <= set(default) and all(_same(v, default[k]) for k, v in value.items())
    if isinstance(value, list) and isinstance(default, list):
        return len(value) == len(default) and all(_same(v, d) for v, d in zip(value, default, strict=True))
    if isinstance(value, bool) or isinstance(default, bool):
        return type(value) is type(default) and value == default
    if isinstance(value, int | float) and isinstance(default, int | float):
        return float(value) == float(default)
    return type(value) is type(default) and value == default


def differences(file: str, node: Mapping[str, Any], defaults: Mapping[str, Any], prefix: str) -> list[str]:
    """One line per key of ``node`` that is not its default (and not in DIFFERS), nor a known setting."""
    found = []
    for key, value in node.items():
        dotted = f"{prefix}{key}"
        if key in HYDRA_KEYS or _is_interpolation(value):
            continue
        if key not in defaults:
            found.append(f"conf/{file}: {dotted} is no setting of what reads it (known: {sorted(defaults)})")
            continue
        default = defaults[key]
        if isinstance(value, Mapping) and isinstance(default, Mapping):
            found += differences(file, value, default, f"{dotted}.")
        elif default is NO_DEFAULT or (file, dotted) in DIFFERS:
            continue
        elif not _same(value, default):
            found.append(f"conf/{file}: {dotted} is {value!r} in the YAML but {default!r} in the code")
    return found


def _node(file: str, path: tuple[str, ...]) -> Mapping[str, Any]:
    node = yaml.safe_load((CONF / file).read_text())
    for key in path:
        node = node[key]
    return node


@pytest.mark.parametrize(("file", "path", "defaults"), PAIRS, ids=[f"{f}:{'.'.join(p)}" for f, p, _ in PAIRS])
def test_every_key_of_the_yaml_equals_the_default_of_its_setting(file, path, defaults):
    # A failure names the key, the YAML's value and the code's: make them one value (the YAML's is what the
    # command line runs with), or, for a setting this file changes on purpose, add it to DIFFERS with the reason.
    prefix = "".join(f"{key}." for key in path)
    found = differences(file, _node(file, path), defaults, prefix)
    assert not found, "\n".join(found)


def test_every_exception_is_still_a_difference():
    """A DIFFERS entry whose key now equals its default (or no longer exists) is stale: remove it."""
    stale = []
    for (file, dotted), _reason in DIFFERS.items():
        pairs = [(p, d) for f, p, d in PAIRS if f == file and dotted.startswith("".join(f"{k}." for k in p))]
        assert pairs, f"conf/{file}: no PAIRS entry reads {dotted}"
        path, defaults = max(pairs, key=lambda pair: len(pair[0]))
        value, default = _node(file, path), defaults
        for key in dotted.split(".")[len(path) :]:
            if not isinstance(value, Mapping) or key not in value:
                stale.append(f"conf/{file}: {dotted} is not in the file")
                break
            value, default = value[key], default[key]
        else:
            if _same(value, default):
                stale.append(f"conf/{file}: {dotted} equals its default {default!r}")
    assert not stale, "stale DIFFERS entries:\n" + "\n".join(stale)


def test_every_config_file_is_compared_or_has_no_counterpart():
    compared = {file for file, _, _ in PAIRS}
    for path in sorted(CONF.rglob("*.yaml")):
        file = path.relative_to(CONF).as_posix()
        listed = file in NO_COUNTERPART or any(file.startswith(d) for d in NO_COUNTERPART if d.endswith("/"))
        assert file in compared or listed, f"conf/{file}: add it to PAIRS (what reads it) or NO_COUNTERPART (why not)"
