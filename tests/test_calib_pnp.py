"""PnP of one view (``vical.calib.solve.initialization.pnp``): a pose where OpenCV's IPPE fails, never a
non-finite one."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vical.calib.solve.initialization import pnp, undistorted
from vical.calib.solve.observations import FrameObservation
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
def test_the_view_gets_the_pose_an_independent_solver_finds(view, refine):
    camera, obs = view
    T, rms = pnp(camera, obs, refine=refine)
    assert rms < 1.0  # [px] 0.25 px of corner noise, and a sensor whose intrinsics differ from the nominal ones here
    xy = undistorted(camera, obs.uv)
    ok, rvec, tvec = cv2.solvePnP(obs.points, xy, np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP)
    assert ok
    np.testing.assert_allclose(T[:3, 3], tvec.ravel(), atol=2e-3)  # [m] at 0.8 m
    np.testing.assert_allclose(T[:3, :3], cv2.Rodrigues(rvec)[0], atol=2e-3)


def test_an_ippe_answer_that_is_not_finite_falls_back_to_the_iterative_solver(view, monkeypatch):
    """Whatever OpenCV build runs the tests: IPPE made to answer NaN, the iterative solver gives the pose."""
    camera, obs = view
    solve = cv2.solvePnP
    nan = np.full((3, 1), np.nan)

    def ippe_fails(*args, flags, **kwargs):
        return (True, nan, nan) if flags == cv2.SOLVEPNP_IPPE else solve(*args, flags=flags, **kwargs)

    monkeypatch.setattr(cv2, "solvePnP", ippe_fails)
    T, rms = pnp(camera, obs, refine=False)
    assert np.all(np.isfinite(T)) and rms < 1.0
    monkeypatch.setattr(cv2, "solvePnP", lambda *args, **kwargs: (True, nan, nan))
    assert pnp(camera, obs, refine=False) is None  # no solver finds a pose: a failed view
