"""vical-train: every config composes and validates; a killed run resumed from its directory ends exactly as an
uninterrupted run (SIGKILL of a real subprocess mid-run); Ctrl-C says how to resume; a finished run is complete,
never shortened, and goes on exactly when resumed longer; user errors are one line and exit status 2; resume
overrides other than key=value changes of existing keys are refused by name."""

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from test_rl_vector import FAIL_RESET, reset_seed

from vical.apps.train import check_command_line, resumed_config
from vical.config_checks import ConfigError
from vical.rl.checkpoint import AGENT, CHECKPOINT, load_checkpoint
from vical.rl.envs import make_env
from vical.rl.run_settings import parse_settings
from vical.rl.trainer import train

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
TINY = [
    "agent.hidden_sizes=[16,16]",
    "agent.batch_size=32",
    "+env.max_episode_steps=50",
    "torch_threads=1",
    "train.total_steps=600",
    "train.warmup_steps=100",
    "train.checkpoint_every=100",
    "train.eval_every=300",
    "train.eval_episodes=1",
    "train.plot_every_episodes=10",
    "train.progress=false",
]


def composed(overrides: list[str]):
    with initialize_config_dir(str(CONF), version_base="1.3"):
        return compose("train", overrides=overrides)


@pytest.mark.parametrize("agent", ["sac", "sac_authors"])
def test_every_agent_config_composes_validates_and_builds_its_env(tmp_path, agent):
    cfg = composed([f"agent={agent}", f"run_dir={tmp_path}"])
    settings = parse_settings(cfg)
    assert isinstance(make_env(settings.env).unwrapped, gym.Env)
    assert settings.agent.hidden_sizes == [256, 256] and settings.torch_threads == 2
    if agent == "sac_authors":  # the calibration paper's authors' settings
        a = settings.agent
        assert (a.gamma, a.tau, a.lr, a.batch_size, a.n_q, a.alpha) == (0.9, 0.01, 3e-4, 128, 1, 1.0)


def run_app(*args: str, cwd: Path) -> subprocess.Popen:
    """``vical-train`` in a subprocess started outside the repository (the app must find its config anyway)."""
    return subprocess.Popen(
        [str(Path(sys.executable).parent / "vical-train"), *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def kill_after_first_checkpoint(proc: subprocess.Popen, checkpoint: Path, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not checkpoint.exists():
        assert proc.poll() is None, f"vical-train exited before its first checkpoint:\n{proc.stdout.read()}"
        assert time.monotonic() < deadline, "no checkpoint appeared"
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()


@pytest.mark.integration
@pytest.mark.parametrize("num_envs, total_steps", [(1, 600), (2, 300)])
def test_killed_run_resumes_to_the_same_parameters_as_an_uninterrupted_run(tmp_path, num_envs, total_steps):
    """SIGKILL of vical-train itself (with 2 envs its worker processes lose their parent mid-episode)."""
    run = tmp_path / "run"
    settings = [*TINY, f"train.num_envs={num_envs}", f"train.total_steps={total_steps}"]
    proc = run_app(*settings, f"hydra.run.dir={run}", cwd=tmp_path)
    kill_after_first_checkpoint(proc, run / CHECKPOINT)
    assert proc.returncode == -signal.SIGKILL
    killed_at = load_checkpoint(run / CHECKPOINT)["counters"]["step"]
    assert 100 <= killed_at < total_steps and not (run / AGENT).exists()

    if num_envs == 1:  # a resume that changes a setting which alters the numbers is refused, naming it
        refused = run_app(f"resume={run}", "agent.gamma=0.5", cwd=tmp_path)
        out = refused.communicate(timeout=120)[0]
        assert refused.returncode == 2 and "agent.gamma: 0.99 (checkpoint) vs 0.5 (now)" in out
        assert out.startswith("vical-train: error: checkpoint") and "Traceback" not in out

    resumed = run_app(f"resume={run}", cwd=tmp_path)
    out = resumed.communicate(timeout=300)[0]
    assert resumed.returncode == 0, out
    assert f"from step {killed_at}" in out and f"trained {total_steps} steps" in out

    full = train(composed([*settings, f"run_dir={tmp_path / 'full'}"]))
    final = torch.load(run / AGENT, weights_only=True)["model"]
    expected = full.agent.state_dict()
    assert final.keys() == expected.keys()
    for key, value in expected.items():
        assert torch.equal(final[key], value), key


@pytest.mark.integration
def test_an_env_that_raises_in_its_reset_is_one_error_line_naming_its_seed_and_the_checkpoint(tmp_path):
    fragile = ["~env.id", "env._target_=test_rl_vector.FragilePendulum"]  # 50-step episodes of its own
    tiny = [a for a in TINY if not a.startswith(("+env.", "train.checkpoint_every"))]
    settings = [*tiny, *fragile, "train.num_envs=2", "train.checkpoint_every=50"]
    seed = reset_seed(env=1, episode=1)  # env 1's second episode: after the checkpoint at step 50
    path = os.pathsep.join([str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")])  # the env's module
    environment = {**os.environ, FAIL_RESET: str(seed), "PYTHONPATH": path}
    run = tmp_path / "run"
    done = subprocess.run(
        [str(Path(sys.executable).parent / "vical-train"), *settings, f"run_dir={run}"],
        cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 2, done.stdout + done.stderr
    (line,) = done.stderr.splitlines()
    assert re.fullmatch(
        rf"vical-train: error: env worker 1 failed to reset its episode of seed {seed} \(RuntimeError: the simulator "
        rf"could not place its arm\) at step \d+; resume from its checkpoint at step 50: vical-train resume={run}",
        line,
    ), line
    assert load_checkpoint(run / CHECKPOINT)["counters"]["step"] == 50


@pytest.mark.integration
def test_a_bad_value_is_one_error_line_and_exit_status_2(tmp_path):
    proc = run_app("train.total_steps=0", f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    out = proc.communicate(timeout=120)[0]
    assert proc.returncode == 2, out
    assert out == "vical-train: error: train.total_steps must be a number in [1, inf), got 0\n"


@pytest.mark.integration
def test_resume_of_a_missing_directory_is_refused_creating_nothing(tmp_path):
    proc = run_app("resume=runs/typo", cwd=tmp_path)
    out = proc.communicate(timeout=120)[0]
    assert proc.returncode == 2, out
    assert out.startswith("vical-train: error: resume must be a run directory") and "'runs/typo' does not exist" in out
    assert list(tmp_path.iterdir()) == []  # neither runs/typo nor any other output directory


@pytest.fixture
def saved_run(tmp_path) -> Path:
    """A run directory whose config.yaml is a complete (composed, validated) config."""
    cfg = OmegaConf.to_container(composed([f"run_dir={tmp_path}"]), resolve=True)
    OmegaConf.save(OmegaConf.create(cfg), tmp_path / "config.yaml")
    return tmp_path


def test_a_run_dir_holding_a_run_is_refused_unless_resumed_or_overwritten(saved_run):
    """A finished (or any) run is never trained over: its agent, config and TensorBoard events would mix with the
    new run's."""
    with pytest.raises(ConfigError) as err:
        check_command_line([*TINY, f"run_dir={saved_run}"])
    assert str(err.value) == (
        f"run_dir={saved_run} holds a vical-train run (config.yaml); continue it with resume={saved_run}, choose "
        "another run_dir, or pass overwrite=true to replace it once the new run is complete"
    )
    assert check_command_line([*TINY, f"run_dir={saved_run}", "overwrite=true"]) is None


def test_resume_applies_key_value_overrides_to_the_saved_config(saved_run):
    overrides = [
        f"resume={saved_run}",
        "train.total_steps=20000",
        "train.info_prefixes=[calib/]",
        "train.progress=false",
    ]
    cfg = resumed_config(str(saved_run), overrides)
    assert cfg.train.total_steps == 20000 and cfg.train.info_prefixes == ["calib/"] and cfg.train.progress is False
    assert cfg.resume == str(saved_run) and cfg.run_dir == str(saved_run)
    assert cfg.agent.gamma == 0.99 and cfg.train.warmup_steps == 1000  # everything else as saved


@pytest.mark.parametrize(
    "override, reason",
    [
        ("agent=sac_authors", "a config group selection: the saved config already fixes agent"),
        ("env=pendulum", "a config group selection: the saved config already fixes env"),
        ("~train.total_steps", "a deletion"),
        ("+train.total_steps=5", "an addition"),
        ("++agent.gamma=0.5", "an addition"),
        ("+sede=3", "an addition"),
        ("sede=3", "unknown key 'sede'"),
        ("train.evaluate_every=5", "unknown key 'train.evaluate_every'"),
        ("train=5", "train is a section"),
    ],
)
def test_resume_refuses_overrides_that_are_not_changes_of_saved_keys(saved_run, override, reason):
    with pytest.raises(ConfigError) as err:
        resumed_config(str(saved_run), [f"resume={saved_run}", "train.total_steps=20000", override])
    message = str(err.value)
    assert f"{override} ({reason}" in message
    assert "train.total_steps=20000 (" not in message  # the valid override is not listed


def test_resume_lists_every_refused_override(saved_run):
    with pytest.raises(ConfigError) as err:
        resumed_config(str(saved_run), ["agent=sac_authors", "~train.total_steps", "+foo=1"])
    assert all(name in str(err.value) for name in ("agent=sac_authors (", "~train.total_steps (", "+foo=1 ("))


@pytest.mark.integration
def test_overwrite_replaces_a_run_only_once_the_new_run_is_complete(tmp_path):
    run = tmp_path / "run"
    assert run_app(*TINY, "train.total_steps=300", f"run_dir={run}", cwd=tmp_path).wait(timeout=300) == 0
    old = load_checkpoint(run / AGENT)["config"]["train"]["total_steps"]
    proc = run_app(*TINY, "train.total_steps=400", f"run_dir={run}", "overwrite=true", cwd=tmp_path)
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, out
    assert (old, load_checkpoint(run / AGENT)["config"]["train"]["total_steps"]) == (300, 400)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing left aside
    assert f"replaced the run in {run}" in out


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_ctrl_c_says_where_the_last_checkpoint_is_and_how_to_resume(tmp_path, sig, status, name):
    run = tmp_path / "run"
    proc = run_app(*TINY, "train.total_steps=100000", f"run_dir={run}", cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not (run / CHECKPOINT).exists():
        assert proc.poll() is None and time.monotonic() < deadline, proc.stdout.read()
        time.sleep(0.01)
    proc.send_signal(sig)
    out = proc.communicate(timeout=60)[0]
    assert proc.returncode == status, out
    step = load_checkpoint(run / CHECKPOINT)["counters"]["step"]
    assert out.splitlines()[-1] == (
        f"vical-train: interrupted ({name}); the last checkpoint (step {step}) is {run / CHECKPOINT}; "
        f"continue with: vical-train resume={run}"
    )
    assert "Traceback" not in out and "KeyboardInterrupt" not in out
    assert [p.name for p in tmp_path.iterdir()] == ["run"] and (run / "train.log").is_file()  # no runs/<time>/


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A run of TINY trained to its end (600 steps, checkpoints every 100)."""
    run = tmp_path_factory.mktemp("finished") / "run"
    train(composed([*TINY, f"run_dir={run}"]))
    return run


def test_a_finished_run_resumed_at_its_length_is_complete_and_never_shortened(finished_run):
    agent = (finished_run / AGENT).read_bytes()
    done = check_command_line([f"resume={finished_run}"])
    assert (
        done == f"run {finished_run} is complete: it trained 600 steps and wrote {finished_run / AGENT}; nothing to do"
    )
    shorter = r"train.total_steps=300 is below the 600 steps run .* finished with: a run cannot be shortened"
    with pytest.raises(ConfigError, match=shorter):
        check_command_line([f"resume={finished_run}", "train.total_steps=300"])
    assert (finished_run / AGENT).read_bytes() == agent


@pytest.mark.integration
def test_a_finished_run_resumed_longer_equals_a_run_of_that_length(finished_run, tmp_path):
    longer = tmp_path / "longer"
    shutil.copytree(finished_run, longer)
    assert check_command_line([f"resume={longer}", "train.total_steps=800"]) is None
    resumed = train(resumed_config(str(longer), [f"resume={longer}", "train.total_steps=800"]))
    full = train(composed([*TINY, "train.total_steps=800", f"run_dir={tmp_path / 'full'}"]))
    assert resumed.steps == full.steps == 800
    for key, value in full.agent.state_dict().items():
        assert torch.equal(resumed.agent.state_dict()[key], value), key


def test_a_finished_run_without_checkpoint_is_complete_but_cannot_go_on(tmp_path):
    run = tmp_path / "run"
    train(composed([*TINY, "train.total_steps=150", "train.checkpoint_every=0", f"run_dir={run}"]))
    assert "is complete: it trained 150 steps" in check_command_line([f"resume={run}"])
    with pytest.raises(ConfigError, match="finished at 150 steps without a checkpoint to go on from"):
        check_command_line([f"resume={run}", "train.total_steps=300"])
