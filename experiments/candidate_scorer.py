"""Can a network rank the information-rate planner's candidates without its lookahead? The offline test of a learned
policy that chooses among moves (a scorer's argmax) instead of averaging them (a distilled mean action).

Runs the rate planner (``rate_planner_demonstrator``'s candidates per task) on the env of a vical-train run (``--run``:
its config.yaml) on tuning sensors, and keeps at every planned step the policy's observation, the coverage state's
terms and the covariance's, every candidate (the policy's [-1, 1] units), the excess the lookahead predicts it sheds
and its predicted recording time (motion + rest). Fits a network ``f(state, action)`` to the candidates of the
training sensors and ranks the candidates of the other sensors by it, in two forms:

- ``rate``: ``f`` fitted to the planner's own score (excess shed per second), centred per state (its argmax needs
  the ranking within a state, not the state's level), and argmax of ``f``;
- ``shed / time``: ``f`` fitted to the excess shed and argmax of ``f / time``: the time of a move is known without
  the lookahead (the step timing's motion fit), so the network learns only what the views add;

each with the policy's observation alone, with the coverage state's 18 terms beside it (what views the data holds, which
the 13-number information state does not say) and with those and 17 terms of the predicted covariance (the intrinsics'
sigmas and correlations, the extrinsic's axes and the time offset: which directions the data pins down), and with either
beside each candidate's predicted views (``view_terms``: the board's image footprint halfway along the move and at its
goal, and how many predicted frames see it; ``--states`` picks the variants). Prints per task the regret of each choice
(the best candidate's rate less the chosen one's, over the state's range of rates: 0 is the planner's choice, a uniform
random candidate's is the mean), on the test sensors and on the states it was fitted to (can it even fit them?).

    .venv/bin/python experiments/candidate_scorer.py --run runs/distill_ctx_s0 --workers 2 --cache decisions.pkl
"""

from __future__ import annotations

import argparse
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from omegaconf import OmegaConf

from vical.env.coverage import view_features
from vical.env.lookahead import Lookahead, Prediction
from vical.io.atomic import atomic_file
from vical.parallel import ParallelConfig, imap_ordered
from vical.policies.greedy import candidate_actions, predicted_moves
from vical.policies.rate_planner import RatePlannerPolicy, TaskRatePlanners, rate_planner_demonstrator
from vical.rl.envs import BoxActions, make_env

_ENVS: dict[str, tuple] = {}


class Variant(NamedTuple):
    """One of the scorer's inputs: its table label, the Decision's state terms beside the policy's observation (the
    coverage state's, the predicted covariance's: ``covariance_terms``) and whether each candidate's views
    (``view_terms``) go beside its action."""

    label: str
    state_terms: tuple[str, ...]
    with_views: bool


STATES = {
    "": Variant("observation", (), False),
    "coverage": Variant("observation + coverage", ("coverage",), False),
    "covariance": Variant("observation + coverage + covariance", ("coverage", "covariance"), False),
    "geometry": Variant("observation + coverage + each candidate's views", ("coverage",), True),
    "geometry+covariance": Variant(
        "observation + coverage + covariance + each candidate's views", ("coverage", "covariance"), True
    ),
}
FOOTPRINT_TERMS = 9  # ``footprint``'s


@dataclass
class Decision:
    """One planned step: the state's features, its candidates and what the lookahead predicts of each."""

    task: str
    obs: np.ndarray  # the policy's observation
    coverage: np.ndarray  # (18,) the coverage state's terms
    covariance: np.ndarray  # (17,) the information's terms (``covariance_terms``)
    actions: np.ndarray  # (C, 6) the candidates, policy units
    shed: np.ndarray  # (C,) predicted e-folds of excess shed
    seconds: np.ndarray  # (C,) predicted recording time: motion + rest
    views: np.ndarray  # (C, 19) what each candidate's move would show the camera (``view_terms``)

    @property
    def rate(self) -> np.ndarray:
        return self.shed / self.seconds


class RecordingRatePlanner(RatePlannerPolicy):
    """The rate planner, keeping every planned step's state, candidates and predictions in ``decisions``."""

    def __init__(self, samples: int, decisions: list[Decision]) -> None:
        super().__init__({}, None, samples, "information-rate planner (recording)")
        self.decisions = decisions

    def _best(self, lookahead: Lookahead, env) -> np.ndarray:
        candidates = candidate_actions(env.action_space.high, self.samples, self._rng)
        actions, predictions = predicted_moves(lookahead, candidates)
        if not actions:
            return self._toward_start(env)
        box = BoxActions(env.action_space)
        self.decisions.append(
            Decision(
                env.task.name,
                env.state.observation(env.pose_offset, env.steps),  # what the policy sees, as the env builds it
                env.state.coverage.vector().astype(np.float32),
                covariance_terms(env.state.information),
                np.array([box.to_policy(a) for a in actions]),
                np.array([env.state.excess - p.excess for p in predictions]),
                np.array([p.motion_time + env.step_timing.rest for p in predictions]),
                np.array([view_terms(lookahead, p) for p in predictions], dtype=np.float32),
            )
        )
        return actions[self.choice(lookahead, predictions, env)]


def recording_planners(decisions: list[Decision]) -> TaskRatePlanners:
    """The teacher distillation uses (``rate_planner_demonstrator``: its candidates per task), recording."""
    teacher = rate_planner_demonstrator()
    teacher.planners = {task: RecordingRatePlanner(p.samples, decisions) for task, p in teacher.planners.items()}
    teacher.default = RecordingRatePlanner(teacher.default.samples, decisions)
    return teacher


def covariance_terms(tracker) -> np.ndarray:
    """(17,) what the predicted covariance says beyond the groups' ratios: log10 of the 1-sigma of fx, fy, cx, cy
    [px], their 6 correlations, log10 of the extrinsic's 6 axes' and the time offset's 1-sigma [rad, m, s] (0 where
    the task estimates none)."""
    names, cov = tracker.covariance()
    sigma = np.sqrt(np.diag(cov))
    k = [i for i, n in enumerate(names) if n == "K"][:4]
    K = cov[np.ix_(k, k)] / np.outer(sigma[k], sigma[k])
    e = [i for i, n in enumerate(names) if n in ("E", "D")]
    inertial = np.log10(sigma[e]) if e else np.zeros(7)
    return np.r_[np.log10(sigma[k]), K[np.triu_indices(4, 1)], inertial].astype(np.float32)


def footprint(lookahead: Lookahead, offset: np.ndarray) -> np.ndarray:
    """(9,) the board's predicted image footprint from the workspace ``offset`` (the lookahead's board and guessed
    camera, the detector's rules): the share of its corners seen, the coverage state's view features (the board's
    centre in the image, its area, its skew), the corners' mean and largest distance from the image centre over the
    half diagonal (how far out the lens's distortion is sampled) and their spread in u and v; zeros beside the share
    when too few are seen."""
    camera = lookahead.tracker.guess.camera
    target = lookahead.tracker.target
    uv, ids = lookahead.board.ideal_observation(camera, lookahead.camera_pose(offset))
    seen = len(ids) / len(target.points)
    features = view_features(uv, ids, target, camera.width, camera.height)
    if features is None:
        return np.r_[seen, np.zeros(FOOTPRINT_TERMS - 1)]
    size = np.array([camera.width, camera.height], dtype=float)
    radius = np.linalg.norm(uv - size / 2, axis=1) / (np.linalg.norm(size) / 2)
    spread = uv.std(axis=0) / size
    return np.r_[seen, features.vector, radius.mean(), radius.max(), spread]


def view_terms(lookahead: Lookahead, prediction: Prediction) -> np.ndarray:
    """(19,) what a candidate's move would show the camera: the board's footprint halfway along it and at its goal
    (``footprint``; the straight offset line's midpoint, where the minimum-jerk profile is halfway) and how many
    predicted frames see the board (over 10)."""
    halfway = footprint(lookahead, (lookahead.offset + prediction.goal) / 2)
    return np.r_[halfway, footprint(lookahead, prediction.goal), prediction.views / 10.0]


def episode(job: tuple[str, int]) -> list[Decision]:
    """The planner's decisions over the episode of sensor ``seed`` on the env of the run config at ``path``."""
    path, seed = job
    if path not in _ENVS:
        decisions: list[Decision] = []
        env = make_env(OmegaConf.to_container(OmegaConf.load(path).env, resolve=True))
        _ENVS[path] = (env, recording_planners(decisions), decisions)
    env, planners, decisions = _ENVS[path]
    decisions.clear()
    obs, _ = env.reset(seed=seed)
    planners.reset(env.unwrapped, np.random.default_rng(seed))
    while True:
        obs, _, terminated, truncated, _ = env.step(planners.act(obs, env.unwrapped))
        if terminated or truncated:
            return list(decisions)


class Scorer(torch.nn.Module):
    """``f(state, candidate)``: two hidden layers of 256 on ``inputs`` numbers."""

    def __init__(self, inputs: int) -> None:
        super().__init__()
        self.mlp = torch.nn.Sequential(
            torch.nn.Linear(inputs, 256), torch.nn.ReLU(), torch.nn.Linear(256, 256), torch.nn.ReLU(),
            torch.nn.Linear(256, 1),
        )  # fmt: skip

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mlp(x).squeeze(-1)


def state_of(d: Decision, state: str) -> np.ndarray:
    """The scorer's input of ``d``'s state (a key of ``STATES``; its candidates' views are ``candidate_terms``')."""
    return np.concatenate([d.obs, *(getattr(d, term) for term in STATES[state].state_terms)])


def candidate_terms(d: Decision, state: str) -> np.ndarray:
    """(C, K) each candidate's input beside the state: its action, with its views where ``state`` includes them."""
    return np.hstack([d.actions, d.views]) if STATES[state].with_views else d.actions


def flat(decisions: list[Decision], state: str, target: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every candidate's input (state, action), its target and its state's index."""
    rows, targets, index = [], [], []
    for k, d in enumerate(decisions):
        features = state_of(d, state)
        rows.append(np.hstack([np.tile(features, (len(d.actions), 1)), candidate_terms(d, state)]))
        targets.append(d.rate if target == "rate" else d.shed)
        index.append(np.full(len(d.actions), k))
    return (
        torch.tensor(np.vstack(rows), dtype=torch.float32),
        torch.tensor(np.concatenate(targets), dtype=torch.float32),
        torch.tensor(np.concatenate(index)),
    )


def centred(values: torch.Tensor, index: torch.Tensor, states: int) -> torch.Tensor:
    """``values`` less the mean of their state's."""
    sums = torch.zeros(states).index_add_(0, index, values)
    counts = torch.zeros(states).index_add_(0, index, torch.ones_like(values))
    return values - (sums / counts)[index]


def fit(decisions: list[Decision], state: str, target: str, epochs: int, seed: int) -> Scorer:
    """The scorer fitted to the candidates of ``decisions``, each state's spread of the target as its unit; a rate
    centred per state (its argmax needs the ranking within a state), the excess shed as it is (divided by the
    time, its level matters)."""
    x, y, index = flat(decisions, state, target)
    states = len(decisions)
    spread = torch.zeros(states).index_add_(0, index, centred(y, index, states) ** 2) / torch.bincount(index)
    unit = spread.sqrt().clamp_min(1e-6)[index]
    if target == "rate":
        y = centred(y, index, states)
    torch.manual_seed(seed)
    scorer = Scorer(x.shape[1])
    optimiser = torch.optim.Adam(scorer.parameters(), lr=1e-3)
    generator = np.random.default_rng(seed)
    for _ in range(epochs):
        for batch in np.array_split(generator.permutation(states), max(states // 32, 1)):
            rows = torch.isin(index, torch.as_tensor(batch))
            predicted = scorer(x[rows])
            if target == "rate":
                remap = torch.full((states,), -1, dtype=torch.long)
                remap[torch.as_tensor(batch)] = torch.arange(len(batch))
                predicted = centred(predicted, remap[index[rows]], len(batch))
            optimiser.zero_grad()
            (((predicted - y[rows]) / unit[rows]) ** 2).mean().backward()
            optimiser.step()
    return scorer


def regret(scorer: Scorer | str, decisions: list[Decision], state: str, target: str) -> float:
    """The mean over states of the best candidate's rate less the chosen one's, over the state's range of rates, of
    the scorer's choice, or of ``"random"`` (the mean over the candidates: a uniform random choice) or
    ``"quickest"`` (the shortest move)."""
    regrets = []
    for d in decisions:
        rate = d.rate
        if scorer == "random":
            chosen = float(rate.mean())
        elif scorer == "quickest":
            chosen = float(rate[np.argmin(d.seconds)])
        else:
            x, _, _ = flat([d], state, target)
            with torch.no_grad():
                f = scorer(x).numpy()
            chosen = float(rate[np.argmax(f / d.seconds if target == "shed" else f)])
        span = rate.max() - rate.min()
        regrets.append((rate.max() - chosen) / span if span > 0 else 0.0)
    return float(np.mean(regrets))


def of(decisions: list[Decision], task: str) -> list[Decision]:
    """The decisions of ``task``."""
    return [d for d in decisions if d.task == task]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, required=True, help="a vical-train run directory (its env)")
    parser.add_argument("--train-seeds", type=int, nargs=2, default=[41100, 41140], help="sensor seeds [from, to)")
    parser.add_argument("--test-seeds", type=int, nargs=2, default=[41140, 41160], help="sensor seeds [from, to)")
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--states", nargs="+", choices=list(STATES), default=list(STATES), help="the inputs to fit on")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--cache", type=Path, help="the planner's decisions kept here, and read from here if it exists")
    args = parser.parse_args()
    config = args.run / "config.yaml"
    if not config.is_file():
        parser.error(f"--run {args.run}: no config.yaml there; name a vical-train run directory")
    seeds = [*range(*args.train_seeds), *range(*args.test_seeds)]
    if args.cache is not None and args.cache.is_file():
        episodes = pickle.loads(args.cache.read_bytes())
    else:
        episodes = list(imap_ordered(episode, [(str(config), s) for s in seeds], ParallelConfig(workers=args.workers)))
        if args.cache is not None:
            with atomic_file(args.cache) as tmp:
                tmp.write_bytes(pickle.dumps(episodes))
    cut = len(range(*args.train_seeds))
    train = [d for e in episodes[:cut] for d in e]
    test = [d for e in episodes[cut:] for d in e]
    tasks = sorted({d.task for d in test})
    print(f"{len(train)} planned steps to fit ({cut} sensors), {len(test)} to test ({len(seeds) - cut} sensors)\n")
    print("| choice | " + " | ".join(f"{t}: regret (test) | {t}: regret (fitted states)" for t in tasks) + " |")
    print("|---|" + "---|---|" * len(tasks))

    def row(name: str, scorer: Scorer | str, state: str = "", target: str = "rate") -> None:
        cells = [
            (regret(scorer, of(test, t), state, target), regret(scorer, of(train, t), state, target)) for t in tasks
        ]
        print(f"| {name} | " + " | ".join(f"{a:.2f} | {b:.2f}" for a, b in cells) + " |", flush=True)

    row("a random candidate", "random")
    row("the quickest candidate", "quickest")
    for state in args.states:
        label = STATES[state].label
        for target in ("rate", "shed"):
            scorer = fit(train, state, target, args.epochs, seed=0)
            row(f"{'rate' if target == 'rate' else 'shed / time'}, {label}", scorer, state, target)


if __name__ == "__main__":
    main()
