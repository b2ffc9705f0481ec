"""Benchmark of the information state: what it adds to an environment step, side by side with the coverage state.

The same sensors (reset seeds 31000..) and the same random actions run through the calibration env
with ``state: coverage`` and with ``state: information`` (joint task, practitioner's workspace),
alternating episode by episode so that both see the same machine load. The difference of the median
step times is the information state's cost (target: about 20 ms, and never more than the step's own
simulation); its share of one step is printed with the frames the step added. A third env adds the
joint task's declared decentred lens (``env.information.center_offset_std=null``): what considering
it costs on top.

    .venv/bin/python experiments/bench_information.py [--episodes 6] [--steps 20]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.rl.envs import make_env

CONF = Path(__file__).resolve().parents[1] / "conf"
FIRST_SEED = 31_000


ENVS = {
    "coverage": ["env.state=coverage"],
    "information": ["env.state=information"],
    "+ lens": ["env.state=information", "env.information.center_offset_std=null"],
}


def env_of(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["env=information", "task=joint", *overrides,
                                                      "env.terminate_on_coverage=false"])  # fmt: skip
    return make_env(OmegaConf.to_container(cfg.env, resolve=True))


def episode(env, seed: int, steps: int) -> list[float]:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    times = []
    for _ in range(steps):
        start = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(rng.uniform(env.action_space.low, env.action_space.high))
        times.append(time.perf_counter() - start)
        if terminated or truncated:
            break
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    envs = {name: env_of(overrides) for name, overrides in ENVS.items()}
    times = {state: [] for state in envs}
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    for k in range(args.episodes):
        for state, env in envs.items():
            times[state] += episode(env, FIRST_SEED + k, args.steps)
    frames = envs["information"].state.information.frames_used / max(envs["information"].steps, 1)
    coverage, information, lens = (1e3 * np.median(times[s]) for s in ENVS)
    print(f"  {'state':<12} {'steps':>5} {'median step [ms]':>17} {'mean [ms]':>10}")
    for state in envs:
        t = 1e3 * np.asarray(times[state])
        print(f"  {state:<12} {len(t):5d} {np.median(t):17.1f} {np.mean(t):10.1f}")
    added = information - coverage
    print(f"information state: +{added:.1f} ms per step ({frames:.1f} frames per step), {added / coverage:.0%} of a "
          "coverage step (target: about 20 ms, below the step itself)")  # fmt: skip
    print(f"the declared decentred lens: +{lens - information:.1f} ms per step on top")
    for env in envs.values():
        env.close()


if __name__ == "__main__":
    main()
