"""experiments/candidate_scorer.py: its regret is 0 for the best choice and the mean for a random one, and its fit
learns a ranking the state and action determine (so a scorer that cannot rank the planner's candidates says
something about the state, not about the fit)."""

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import candidate_scorer  # noqa: E402
from candidate_scorer import Decision, candidate_terms, centred, fit, regret, state_of  # noqa: E402


def decisions(count: int, seed: int) -> list[Decision]:
    """States whose candidates shed excess by a rule of the state and the action, 1 + obs[0] a[0] + a[1] / 2, in a
    time the action sets, 0.5 + 1.5 |a[2]| s (as a move's time follows from the move)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        obs = rng.uniform(-1, 1, 13).astype(np.float32)
        actions = rng.uniform(-1, 1, (24, 6)).astype(np.float32)
        shed = 1.0 + obs[0] * actions[:, 0] + 0.5 * actions[:, 1]
        seconds = 0.5 + 1.5 * np.abs(actions[:, 2])
        views = np.zeros((24, 19), np.float32)
        out.append(
            Decision("joint", obs, np.zeros(18, np.float32), np.zeros(17, np.float32), actions, shed, seconds, views)
        )
    return out


def test_centred_removes_each_state_mean():
    values = torch.tensor([1.0, 3.0, 10.0, 20.0, 30.0])
    index = torch.tensor([0, 0, 1, 1, 1])
    assert torch.allclose(centred(values, index, 2), torch.tensor([-1.0, 1.0, -10.0, 0.0, 10.0]))


def test_regret_of_random_is_the_mean_and_of_the_quickest_its_own():
    d = Decision(
        "joint", np.zeros(13), np.zeros(18), np.zeros(17), np.zeros((3, 6)), np.array([1.0, 2.0, 6.0]), np.ones(3),
        np.zeros((3, 19)),
    )  # fmt: skip
    assert regret("random", [d], "", "rate") == pytest.approx((6.0 - 3.0) / 5.0)
    d.seconds = np.array([0.5, 1.0, 3.0])  # rates 2, 2, 2: every choice is the best
    assert regret("quickest", [d], "", "rate") == 0.0


@pytest.mark.parametrize("target", ["rate", "shed"])
def test_fit_ranks_what_the_state_determines(target):
    scorer = fit(decisions(300, 0), state="", target=target, epochs=30, seed=0)
    test = decisions(100, 1)
    learned, random = regret(scorer, test, "", target), regret("random", test, "", target)
    assert random > 0.3  # the candidates differ
    assert learned < 0.25 * random


def test_views_enter_only_the_geometry_variants():
    d = decisions(1, 0)[0]
    d.views = np.arange(24 * 19, dtype=np.float32).reshape(24, 19)
    assert candidate_terms(d, "coverage").shape == (24, 6)
    assert np.array_equal(candidate_terms(d, "geometry")[:, 6:], d.views)
    assert np.array_equal(state_of(d, "geometry+covariance"), state_of(d, "covariance"))
    assert np.array_equal(state_of(d, "geometry"), state_of(d, "coverage"))


def test_refuses_a_run_without_its_config(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["candidate_scorer.py", "--run", str(tmp_path)])
    with pytest.raises(SystemExit) as ended:
        candidate_scorer.main()
    assert ended.value.code == 2 and "no config.yaml there" in capsys.readouterr().err
