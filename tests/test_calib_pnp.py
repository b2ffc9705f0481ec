"""PnP of one view (``vical.calib.initialization.pnp``): a failed solve is None, never a non-finite pose."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vical.calib.initialization import pnp, undistorted
from vical.calib.observations import FrameObservation
from vical.data import Target
from vical.geometry import CameraModel

VIEW = Path(__file__).parent / "data" / "pnp_ippe_nan_view.csv"


@pytest.fixture(scope="module")
def view():
    """The aprilgrid view of the practitioner's workspace on which OpenCV 5.0's IPPE answered NaN (found in training:
    the information state took the NaN pose and the run stopped on a NaN observation)."""
    rows = np.loadtxt(VIEW, delimiter=",", skiprows=3)
    ids = rows[:, 0].astype(np.int64)
    camera = CameraModel("radtan", 640, 480, 585.7560709479847, 585.7560709479847, 319.5, 239.5)
    return camera, FrameObservation(-1, 0, rows[:, 1:], ids, Target.aprilgrid().points[ids])


@pytest.mark.parametrize("refine", [False, True])
def test_a_view_gives_a_finite_pose_that_reprojects_or_none(view, refine):
    camera, obs = view
    result = pnp(camera, obs, refine=refine)
    if result is None:  # where IPPE fails on it (OpenCV 5.0 on x86-64)
        return
    T, rms = result
    assert np.all(np.isfinite(T)) and rms < 0.5
    # Against OpenCV's iterative solver from scratch: the same pose.
    xy = undistorted(camera, obs.uv)
    ok, rvec, tvec = cv2.solvePnP(obs.points, xy, np.eye(3), None, flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok
    np.testing.assert_allclose(T[:3, 3], tvec.ravel(), atol=1e-3)
    np.testing.assert_allclose(T[:3, :3], cv2.Rodrigues(rvec)[0], atol=1e-3)


def test_a_solver_that_answers_nan_is_a_failed_view(view, monkeypatch):
    """Whatever OpenCV build runs the tests: an IPPE answer that is not finite is no pose."""
    camera, obs = view
    nan = np.full((3, 1), np.nan)
    monkeypatch.setattr(cv2, "solvePnP", lambda *args, **kwargs: (True, nan, nan))
    assert pnp(camera, obs, refine=False) is None
