"""Sweeps and workers from the command line: a local 3-seed sweep in one command, launcher configs, bad input."""

import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from vical.rl.checkpoint import AGENT

pytestmark = pytest.mark.integration  # every test starts console scripts in subprocesses

BIN = Path(sys.executable).parent
SHORT = [
    "+env.max_episode_steps=50",
    "agent.hidden_sizes=[16,16]",
    "agent.batch_size=32",
    "torch_threads=1",
    "train.total_steps=200",
    "train.warmup_steps=100",
    "train.eval_every=0",
    "train.progress=false",
]


def app(name: str, *args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """A console script in a subprocess started outside the repository."""
    return subprocess.run(
        [str(BIN / name), *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, check=False
    )


def test_a_three_seed_sweep_runs_locally_in_parallel_in_one_command(tmp_path):
    sweep = tmp_path / "sweep"
    done = app(
        "vical-train", "-m", "seed=0,1,2", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2",
        f"hydra.sweep.dir={sweep}", *SHORT, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    runs = [sweep / str(k) for k in range(3)]
    weights = [torch.load(run / AGENT, weights_only=True)["model"]["policy.mlp.weights.0"] for run in runs]
    assert not torch.equal(weights[0], weights[1]) and not torch.equal(weights[1], weights[2])  # three seeds
    assert "Joblib.Parallel(n_jobs=2" in done.stdout + done.stderr


def test_the_slurm_launcher_config_composes_with_its_plugin(tmp_path):
    done = app("vical-train", "hydra/launcher=vical_slurm", "hydra.launcher.partition=cpu", "--cfg", "hydra",
               cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    text = done.stdout
    assert "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher" in text
    assert "partition: cpu" in text and "cpus_per_task: 16" in text


def test_a_launcher_without_its_plugin_is_one_line_saying_what_to_install(tmp_path):
    start = time.perf_counter()
    done = app("vical-train", "-m", "hydra/launcher=vical_ray", "seed=0,1", cwd=tmp_path)
    assert done.returncode == 2 and time.perf_counter() - start < 30
    assert done.stderr.strip().splitlines() == [
        "vical-train: error: hydra/launcher=vical_ray needs a Hydra launcher plugin that is not installed: "
        "pip install hydra-ray-launcher (in its own environment)"
    ]


def test_bad_worker_counts_and_an_unreachable_ray_address_are_one_line_within_seconds(tmp_path):
    unreachable = ["parallel=ray", "parallel.ray_address=127.0.0.1:9"]  # the discard port: nothing listens
    num_envs_0 = "train.num_envs must be an integer from 1 to 1024 (env worker processes), got 0"
    cases = [
        ("vical-train", ["train.num_envs=0"], num_envs_0),
        ("vical-train", [*unreachable, "train.num_envs=2"], "nothing answers at 127.0.0.1:9"),
        ("vical-evaluate", ["parallel.workers=5000", "episodes=1"], "parallel.workers must be an integer from 1"),
        ("vical-evaluate", [*unreachable, "episodes=1"], "nothing answers"),
    ]
    for name, args, message in cases:
        start = time.perf_counter()
        out = [f"out={tmp_path / 'eval'}"] if name == "vical-evaluate" else [f"run_dir={tmp_path / 'run'}", *SHORT]
        done = app(name, *args, *out, cwd=tmp_path)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and message in lines[0], done.stderr
        assert time.perf_counter() - start < 60
        assert list(tmp_path.iterdir()) == []  # no run directory, no outputs directory of Hydra's
