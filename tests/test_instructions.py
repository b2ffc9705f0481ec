"""The words that guide a person: each motion in the camera's own axes, largest first, rounded as a hand can follow."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vical.collection.instructions import HOLD_STILL, Wording, instruction
from vical.config_checks import ConfigError
from vical.geometry import make_transform

# A camera before the board, turned so that its axes are not the board's: the words are relative to the camera.
CAMERA = make_transform(Rotation.from_euler("xyz", [3.0, 0.2, -0.4]).as_matrix(), [0.1, 0.2, -0.8])


def _goal(move_cam=(0.0, 0.0, 0.0), turn_cam_deg=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The pose reached from ``CAMERA`` by a move and a turn in its own axes."""
    local = make_transform(Rotation.from_rotvec(np.radians(turn_cam_deg)).as_matrix(), move_cam)
    return CAMERA @ local


@pytest.mark.parametrize(
    ("move", "turn", "words"),
    [
        ((0.0, 0.0, 0.2), (0, 0, 0), "move 20 cm closer"),
        ((0.0, 0.0, -0.31), (0, 0, 0), "move 30 cm farther back"),
        ((0.12, 0.0, 0.0), (0, 0, 0), "move 10 cm right"),
        ((0.0, -0.13, 0.0), (0, 0, 0), "move 15 cm up"),
        ((0, 0, 0), (30, 0, 0), "tilt the top toward you 30 deg"),
        ((0, 0, 0), (-25, 0, 0), "tilt the top away 25 deg"),
        ((0, 0, 0), (0, 40, 0), "turn right 40 deg"),
        ((0, 0, 0), (0, 0, 90), "roll clockwise 90 deg"),
        ((0, 0, 0), (0, 0, -45), "roll counter-clockwise 45 deg"),
        ((0.3, 0.0, 0.0), (0, 20, 0), "move 30 cm right, turn right 20 deg"),  # 30 cm outweighs 20 deg
        ((0.0, 0.0, 0.1), (0, 0, 60), "roll clockwise 60 deg, move 10 cm closer"),
        ((0.3, -0.2, 0.1), (0, 0, 0), "move 30 cm right, move 20 cm up"),  # at most two parts
        ((0.02, 0.0, 0.03), (5, 0, -4), HOLD_STILL),
    ],
)
def test_the_instruction_names_the_motion_in_the_cameras_axes(move, turn, words):
    assert instruction(CAMERA, _goal(move, turn)) == words


def test_the_words_mean_what_the_person_sees():
    """'Tilt the top toward you': the optical axis turns up in the image (-y); 'turn right': toward +x; 'roll
    clockwise': the image's right (+x) turns down (+y) as seen from behind the camera, looking along +z."""
    up = Rotation.from_rotvec(np.radians([20, 0, 0])).apply([0, 0, 1])
    right = Rotation.from_rotvec(np.radians([0, 20, 0])).apply([0, 0, 1])
    rolled = Rotation.from_rotvec(np.radians([0, 0, 20])).apply([1, 0, 0])
    assert up[1] < 0 and right[0] > 0 and rolled[1] > 0


def test_finer_wording_says_more():
    goal = _goal((0.03, 0.0, 0.0), (0, 0, 6))
    assert instruction(CAMERA, goal) == HOLD_STILL
    assert instruction(CAMERA, goal, Wording(min_move=0.01, min_turn=5.0, max_parts=3)) == (
        "roll clockwise 5 deg, move 5 cm right"
    )


@pytest.mark.parametrize(("setting", "value"), [("min_move", 0.0), ("min_turn", -1.0), ("max_parts", 0)])
def test_bad_wording_is_refused_by_key(setting, value):
    with pytest.raises(ConfigError, match=rf"guide\.wording\.{setting} must be"):
        Wording(**{setting: value})
