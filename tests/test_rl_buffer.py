"""Replay buffer: circular overwrite, seeded uniform sampling, termination vs truncation, discounts, save/load."""

import numpy as np
import pytest

from vical.rl.buffer import Batch, ReplayBuffer


def filled(capacity: int, n: int) -> ReplayBuffer:
    """Transition i has obs [i, -i], action [i / 100], reward i, next_obs [i + 1, -i - 1], terminated i % 3 == 0."""
    buf = ReplayBuffer(capacity, obs_dim=2, act_dim=1)
    for i in range(n):
        buf.add(np.array([i, -i]), np.array([i / 100]), float(i), np.array([i + 1, -i - 1]), i % 3 == 0)
    return buf


def test_wrap_around_keeps_the_newest_transitions_in_circular_order():
    buf = filled(capacity=5, n=12)
    assert len(buf) == 5 and buf.position == 2
    # slots 0, 1 were overwritten by transitions 10, 11; slots 2..4 hold 7, 8, 9
    np.testing.assert_array_equal(buf.rewards, [10, 11, 7, 8, 9])
    np.testing.assert_array_equal(buf.obs[:, 0], [10, 11, 7, 8, 9])
    np.testing.assert_array_equal(buf.next_obs[:, 0], [11, 12, 8, 9, 10])
    np.testing.assert_array_equal(buf.terminated, [0, 0, 0, 0, 1])


def test_sampling_returns_whole_transitions_from_stored_slots_only():
    buf = filled(capacity=100, n=10)
    batch = buf.sample(4096, np.random.default_rng(0))
    assert isinstance(batch, Batch)
    assert batch.obs.shape == (4096, 2) and batch.actions.shape == (4096, 1) and batch.rewards.shape == (4096,)
    i = batch.rewards.numpy()
    assert set(i.astype(int)) == set(range(10))  # never an unfilled (zero-initialised) slot beyond the 10 stored
    # every field of a sampled row belongs to the same transition
    np.testing.assert_array_equal(batch.obs[:, 0].numpy(), i)
    np.testing.assert_array_equal(batch.next_obs[:, 0].numpy(), i + 1)
    np.testing.assert_allclose(batch.actions[:, 0].numpy(), i / 100, rtol=1e-6)
    np.testing.assert_array_equal(batch.terminated.numpy(), (i.astype(int) % 3 == 0).astype(np.float32))
    # uniform: each of the 10 transitions appears about 4096 / 10 times (binomial sd ~19)
    counts = np.bincount(i.astype(int), minlength=10)
    assert np.all(np.abs(counts - 409.6) < 5 * 19.2), counts


def test_sampling_is_reproducible_from_the_generator_seed():
    buf = filled(capacity=50, n=50)
    a = buf.sample(32, np.random.default_rng(7)).rewards
    b = buf.sample(32, np.random.default_rng(7)).rewards
    c = buf.sample(32, np.random.default_rng(8)).rewards
    assert a.equal(b) and not a.equal(c)


def test_truncation_is_stored_as_a_non_terminal_transition_with_its_true_next_obs():
    buf = ReplayBuffer(4, obs_dim=1, act_dim=1)
    # a time-limit truncation: gymnasium returns the real final observation and terminated=False
    buf.add(np.array([1.0]), np.array([0.0]), -1.0, np.array([2.0]), terminated=False)
    buf.add(np.array([2.0]), np.array([0.0]), -1.0, np.array([3.0]), terminated=True)
    np.testing.assert_array_equal(buf.terminated[:2], [0.0, 1.0])
    np.testing.assert_array_equal(buf.next_obs[:2, 0], [2.0, 3.0])


def test_a_transitions_own_discount_is_stored_sampled_and_checked():
    buf = ReplayBuffer(8, obs_dim=1, act_dim=1)
    for i in range(4):
        buf.add(np.array([i]), np.array([0.0]), float(i), np.array([i + 1]), False, discount=0.5**i)
    batch = buf.sample(256, np.random.default_rng(0))
    np.testing.assert_allclose(batch.discounts.numpy(), 0.5 ** batch.rewards.numpy())
    np.testing.assert_array_equal(buf.discounts[4:], 1.0)  # unfilled slots and the default: an ordinary step
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="discount must be in"):
            buf.add(np.array([0.0]), np.array([0.0]), 0.0, np.array([0.0]), False, discount=bad)
    assert len(buf) == 4
    buf.add(np.array([0.0]), np.array([0.0]), 0.0, np.array([0.0]), False, discount=0.0)  # nothing after it counts
    assert buf.discounts[4] == 0.0 and buf.terminated[4] == 0.0


def test_a_state_saved_before_per_step_discounts_loads_with_discount_one():
    buf = filled(capacity=6, n=4)
    state = buf.state_dict()
    del state["discounts"]
    restored = ReplayBuffer(6, obs_dim=2, act_dim=1)
    restored.load_state_dict(state)
    np.testing.assert_array_equal(restored.rewards[:4], buf.rewards[:4])
    np.testing.assert_array_equal(restored.discounts, 1.0)


def test_save_load_round_trip_restores_contents_and_write_position(tmp_path):
    buf = filled(capacity=8, n=11)
    buf.save(tmp_path / "buffer.npz")
    assert [p.name for p in tmp_path.iterdir()] == ["buffer.npz"]  # no temp file left behind
    restored = ReplayBuffer(8, obs_dim=2, act_dim=1)
    restored.load(tmp_path / "buffer.npz")
    assert (len(restored), restored.position) == (8, 3)
    for name in ("obs", "actions", "rewards", "next_obs", "terminated"):
        np.testing.assert_array_equal(getattr(restored, name), getattr(buf, name))
    restored.add(np.zeros(2), np.zeros(1), 99.0, np.zeros(2), False)
    assert restored.rewards[3] == 99.0  # continues writing where the saved buffer would have


def test_load_refuses_a_buffer_of_other_dimensions(tmp_path):
    filled(capacity=8, n=3).save(tmp_path / "b.npz")
    with pytest.raises(ValueError, match=r"replay buffer 'obs' has shape \(3,\), saved \(2,\)"):
        ReplayBuffer(8, obs_dim=3, act_dim=1).load(tmp_path / "b.npz")
    with pytest.raises(ValueError, match="capacity 9 differs from the saved 8"):
        ReplayBuffer(9, obs_dim=2, act_dim=1).load(tmp_path / "b.npz")


def test_empty_buffer_and_bad_capacity_give_clear_errors():
    with pytest.raises(ValueError, match="capacity must be >= 1"):
        ReplayBuffer(0, 1, 1)
    with pytest.raises(ValueError, match="empty replay buffer"):
        ReplayBuffer(3, 1, 1).sample(2, np.random.default_rng(0))
