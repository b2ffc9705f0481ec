"""The practitioner's workspace: pose frames, reachability (IK + no contact), bad workspaces and board placements."""

import numpy as np
import pytest
from configs import composed

from vical.config_checks import ConfigError
from vical.env.settings import Workspace
from vical.env.workspace import (
    PoseFrame,
    board_centre,
    check_workspace,
    look_at_rotation,
    pose_frame,
    reachable_fraction,
    unreachable_reason,
)
from vical.geometry import euler_to_matrix, make_transform, rotation_angle
from vical.sim import PandaSim, SimConfig


def practitioner() -> tuple[dict, Workspace]:
    """The practitioner workspace's sim config and workspace, as the apps compose them."""
    cfg = composed("evaluate", ["workspace=practitioner"])
    return cfg["sim"], Workspace(**cfg["env"]["workspace"])


@pytest.fixture(scope="module")
def sim_and_frame():
    sim_cfg, workspace = practitioner()
    sim = PandaSim(SimConfig.from_mapping(sim_cfg))
    return sim, pose_frame(sim, workspace), workspace


def test_look_at_rotation_points_body_x_at_the_target_and_keeps_body_y_level():
    rng = np.random.default_rng(0)
    for _ in range(20):
        p, c = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
        R = look_at_rotation(p, c)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R[:, 0], (c - p) / np.linalg.norm(c - p), atol=1e-12)
        assert abs(R[2, 1]) < 1e-12 and R[2, 2] > 0  # y horizontal, z up
    with pytest.raises(ValueError, match="vertical"):
        look_at_rotation(np.zeros(3), np.array([0.0, 0.0, 1.0]))


@pytest.mark.parametrize("frame", ["start", "board"])
def test_offsets_and_poses_are_inverse(frame):
    T_start = make_transform(euler_to_matrix([0.1, -0.2, 0.3]), [0.4, 0.1, 0.5])
    pf = PoseFrame(T_start, frame, look_at=np.array([1.2, 0.0, 0.4]))
    np.testing.assert_allclose(pf.pose(np.zeros(6)), T_start, atol=1e-12)  # the zero offset is the start pose
    rng = np.random.default_rng(1)
    for offset in rng.uniform(-1, 1, (50, 6)) * [0.3, 0.3, 0.3, 1.5, 0.5, 0.5]:
        np.testing.assert_allclose(pf.offset(pf.pose(offset)), offset, atol=1e-9)


@pytest.mark.parametrize("frame", ["start", "board"])
@pytest.mark.parametrize("heading", [None, np.array([2.0, 0.5, 0.7])])
def test_a_stack_of_offsets_maps_to_the_stack_of_their_poses(frame, heading):
    """The planner maps its predictions' offsets in one pass: each pose of the stack is the one offset's pose, each
    rotation of a stacked look-at or Euler map the single one's; a vertical line of sight anywhere in the stack
    is refused."""
    T_start, look_at = make_transform(euler_to_matrix([0.1, -0.2, 0.3]), [0.4, 0.1, 0.5]), np.array([1.2, 0.0, 0.4])
    pf = PoseFrame(T_start, frame, look_at, heading=heading)
    offsets = np.random.default_rng(3).uniform(-1, 1, (40, 6)) * [0.3, 0.3, 0.3, 1.5, 0.5, 0.5]
    stacked = pf.pose(offsets)
    assert stacked.shape == (40, 4, 4)
    for offset, T in zip(offsets, stacked, strict=True):
        np.testing.assert_allclose(T, pf.pose(offset), atol=1e-12)
    np.testing.assert_allclose(pf.pose(offsets.reshape(4, 10, 6)), stacked.reshape(4, 10, 4, 4), atol=1e-15)
    for angles, R in zip(offsets[:, 3:], euler_to_matrix(offsets[:, 3:]), strict=True):
        np.testing.assert_allclose(R, euler_to_matrix(angles), atol=1e-15)
    positions = offsets[:, :3]
    for position, R in zip(positions, look_at_rotation(positions, look_at), strict=True):
        np.testing.assert_allclose(R, look_at_rotation(position, look_at), atol=1e-15)
    with pytest.raises(ValueError, match="vertical"):
        look_at_rotation(np.vstack([positions[:3], look_at - [0.0, 0.0, 1.0]]), look_at)


@pytest.mark.parametrize("frame", ["start", "board"])
def test_a_heading_gives_a_turned_base_the_offsets_the_world_gives(frame):
    """Poses in a base turned by 1.1 rad about z, with the heading the world's +x has there: every offset is the
    same physical pose, both ways; a vertical heading is refused."""
    turn = make_transform(euler_to_matrix([0.0, 0.0, 1.1]), np.zeros(3))
    T_start, look_at = make_transform(euler_to_matrix([0.1, -0.2, 0.3]), [0.4, 0.1, 0.5]), np.array([1.2, 0.0, 0.4])
    world = PoseFrame(T_start, frame, look_at)
    turned = PoseFrame(turn.T @ T_start, frame, turn[:3, :3].T @ look_at, heading=turn[:3, :3].T @ [2.0, 0.0, 0.7])
    for offset in np.random.default_rng(2).uniform(-1, 1, (30, 6)) * [0.3, 0.3, 0.3, 1.5, 0.5, 0.5]:
        np.testing.assert_allclose(turn @ turned.pose(offset), world.pose(offset), atol=1e-12)
        np.testing.assert_allclose(turned.offset(turn.T @ world.pose(offset)), offset, atol=1e-9)
    with pytest.raises(ValueError, match="vertical"):
        PoseFrame(T_start, frame, look_at, heading=np.array([0.0, 0.0, 1.0]))


def test_zero_angles_in_the_board_frame_look_at_the_board_centre_from_anywhere(sim_and_frame):
    sim, frame, workspace = sim_and_frame
    centre = board_centre(sim)
    rng = np.random.default_rng(2)
    for position in rng.uniform(-1, 1, (20, 3)) * workspace.bound[:3]:
        T = frame.pose(np.r_[position, 0.0, 0.0, 0.0])
        sight = (centre - T[:3, 3]) / np.linalg.norm(centre - T[:3, 3])
        np.testing.assert_allclose(T[:3, 0], sight, atol=3e-5)  # the start pose is reached by IK within 1e-5
    # Yaw turns the camera left, so the board moves to the right of the line of sight.
    T = frame.pose(np.r_[0, 0, 0, 0, 0, 0.3])
    assert rotation_angle(T[:3, :3]) == pytest.approx(0.3)


def test_most_of_the_practitioner_workspace_is_reachable_without_contact(sim_and_frame):
    sim, frame, workspace = sim_and_frame
    reach = reachable_fraction(sim, frame, workspace.bound, samples=80, seed=11)
    # docs/workspace.md: 93 % of 300 samples; the rest is beyond the Panda's reach (near and high, far and low).
    assert reach.reachable >= 0.85, reach
    assert reach.samples == 80 and sum(reach.reasons.values()) == round(80 * (1 - reach.reachable))


def test_a_reachable_pose_is_within_the_joint_limits_free_of_contact_and_executes_in_physics(sim_and_frame):
    sim, frame, workspace = sim_and_frame
    rng = np.random.default_rng(5)
    executed = 0
    for offset in rng.uniform(-1, 1, (12, 6)) * workspace.bound:
        T = frame.pose(offset)
        if unreachable_reason(sim, T):
            continue
        ik = sim.ik.solve(T, sim.q_start, np.random.default_rng(0))
        assert np.all(ik.q >= sim.limits.q_min) and np.all(ik.q <= sim.limits.q_max)
        assert sim.contact_at(ik.q) == ""
        sim.reset()
        motion = sim.move_to(T)
        assert motion.reached, motion.message
        assert np.linalg.norm(sim.ee_pose()[:3, 3] - T[:3, 3]) < 1e-3
        executed += 1
    assert executed >= 8


def test_every_axis_end_of_the_practitioner_workspace_passes_the_check(sim_and_frame):
    sim, frame, workspace = sim_and_frame
    check_workspace(sim, frame, workspace)  # raises for an unreachable axis end


def test_an_unreachable_bound_is_refused_with_the_key_and_the_reachable_range(sim_and_frame):
    sim, frame, workspace = sim_and_frame
    too_far = Workspace(workspace.name, workspace.frame, (0.7, *workspace.position[1:]), workspace.orientation)
    with pytest.raises(ConfigError) as info:
        check_workspace(sim, frame, too_far)
    message = str(info.value)
    assert message.startswith("env.workspace.position (x) = 0.7 m: from the start pose the arm cannot reach +0.7 m")
    low, high = (float(v) for v in message.split("reachable along x: [")[1].split("]")[0].split(","))
    assert low <= -workspace.position[0] and workspace.position[0] <= high < 0.7
    assert not unreachable_reason(sim, frame.pose(np.r_[high, 0, 0, 0, 0, 0]))


def test_an_unreachable_start_pose_is_refused_by_key():
    sim_cfg, _ = practitioner()
    with pytest.raises(ConfigError, match=r"^sim\.start: the arm cannot reach the start pose .* \d+ mm"):
        PandaSim(SimConfig.from_mapping({**sim_cfg, "start": {"position": [1.5, 0.0, 0.4], "rpy": [0, 0, 0]}}))


def test_a_board_the_workspace_runs_into_is_refused_with_the_contact_and_the_reachable_range():
    sim_cfg, _ = practitioner()
    # The board 0.30 m ahead, the workspace 0.33 m toward it: the camera would go through the board.
    sim = PandaSim(SimConfig.from_mapping({**sim_cfg, "board": {**sim_cfg["board"], "distance": 0.3}}))
    into = Workspace("into the board", "start", (0.33, 0.1, 0.1), (0.1, 0.1, 0.1))
    with pytest.raises(ConfigError) as info:
        check_workspace(sim, pose_frame(sim, into), into)
    message = str(info.value)
    assert "+0.33 m (contact: " in message and "board_backing" in message
    high = float(message.split("reachable along x: [")[1].split(",")[1].split("]")[0])
    # The optical centre gets to the board's plane (the camera body lies behind it), within the bisection's 0.3 mm.
    assert 0.295 < high < 0.305


def test_the_stand_holds_the_board_from_the_floor_behind_its_centre(sim_and_frame):
    sim, _, _ = sim_and_frame
    model = sim.model
    post = model.geom("stand_post")
    centre = board_centre(sim)
    top = sim.data.geom_xpos[post.id][2] + model.geom_size[post.id][2]
    bottom = sim.data.geom_xpos[post.id][2] - model.geom_size[post.id][2]
    assert bottom == pytest.approx(0.0, abs=1e-9) and top == pytest.approx(centre[2], abs=1e-9)
    normal = sim.T_world_board[:3, 2]
    assert float(normal @ (sim.data.geom_xpos[post.id] - centre)) < 0  # behind the printed side
    assert model.geom_contype[post.id] and model.geom_conaffinity[post.id]  # the arm can hit it
