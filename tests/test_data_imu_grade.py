"""IMU grades (``vical.data.imu_grade``): the named grades, their imu.yaml keys (``vical.io.kalibr``), the refusals,
and the consider-prior a grade puts on the gyro's scales and misalignments (``ImuModelError.spread``) against the
posterior in information form."""

import math
from dataclasses import replace

import numpy as np
import pytest

from vical.calib.solve.imu_model_error import ACCEL, GYRO, ImuModelError
from vical.data import ImuNoise
from vical.data.errors import DataError
from vical.data.imu_grade import GRADES, REAL_DATA_GRADE, ImuGrade, imu_grade
from vical.io.errors import KalibrFormatError
from vical.io.kalibr import read_imu_grade, read_imu_yaml, write_imu_yaml


def test_the_named_grades_and_the_real_data_default():
    assert (
        GRADES["calibrated"].perfect and not np.any(GYRO.prior(GRADES["calibrated"])) and not np.any(GYRO.prior(None))
    )
    industrial = imu_grade("industrial")
    assert industrial.gyro_scale == 0.005 and industrial.gyro_misalignment == pytest.approx(math.radians(0.2))
    np.testing.assert_allclose(np.diag(GYRO.prior(industrial)), [0.005**2] * 3 + [math.radians(0.2) ** 2] * 3)
    custom = ImuGrade(accel_scale=0.002, accel_misalignment=0.001)
    np.testing.assert_allclose(np.diag(ACCEL.prior(custom)), [0.002**2] * 3 + [0.001**2] * 3)
    assert GRADES["consumer"].gyro_scale > industrial.gyro_scale and REAL_DATA_GRADE in GRADES


@pytest.mark.parametrize(
    ("terms", "named"),
    [({"gyro_scale": -0.001}, "gyro_scale"), ({"accel_scale": 0.2}, "accel_scale"),
     ({"gyro_misalignment": math.inf}, "gyro_misalignment"), ({"accel_misalignment": 0.5}, "accel_misalignment")],
)  # fmt: skip
def test_negative_absurd_or_infinite_terms_are_refused_by_name(terms, named):
    with pytest.raises(DataError, match=f"IMU grade {named} must be a 1-sigma from 0 to 0.1"):
        ImuGrade(**terms)


def test_an_unknown_grade_name_is_refused_with_the_names_there_are():
    with pytest.raises(DataError, match=r"IMU grade 'tactical' does not exist; use one of \['calibrated', 'indus"):
        imu_grade("tactical")


def test_an_imu_yaml_declares_its_grade_by_name_and_by_terms(tmp_path):
    path = tmp_path / "imu.yaml"
    write_imu_yaml(path, ImuNoise())
    assert read_imu_grade(path) is None  # Kalibr's file declares none
    write_imu_yaml(path, ImuNoise(), grade=GRADES["consumer"])
    assert read_imu_grade(path) == GRADES["consumer"] and read_imu_yaml(path) == ImuNoise()
    assert "imu_grade: consumer" in path.read_text() and "_sigma" not in path.read_text()  # a named one by its name
    own = replace(GRADES["consumer"], gyro_scale=0.003)
    write_imu_yaml(path, ImuNoise(), grade=own)
    assert read_imu_grade(path) == own and "imu_grade" not in path.read_text()  # another by its terms
    path.write_text(f"{path.read_text()}imu_grade: calibrated\n")  # terms override the named grade's
    assert read_imu_grade(path) == own
    write_imu_yaml(path, ImuNoise())
    path.write_text(f"{path.read_text()}gyroscope_scale_sigma: 0.002\n")  # the rest: the real-data default's
    assert read_imu_grade(path) == replace(GRADES[REAL_DATA_GRADE], gyro_scale=0.002)
    path.write_text("imu0:\n  imu_grade: consumer\n")  # Kalibr's result layout
    assert read_imu_grade(path) == GRADES["consumer"]


@pytest.mark.parametrize(
    ("line", "key"),
    [("imu_grade: tactical", "imu_grade"), ("gyroscope_scale_sigma: -0.01", "gyroscope_scale_sigma"),
     ("accelerometer_misalignment_sigma: 0.3", "accelerometer_misalignment_sigma")],
)  # fmt: skip
def test_a_bad_grade_key_is_refused_naming_the_file_and_the_key(tmp_path, line, key):
    path = tmp_path / "imu.yaml"
    write_imu_yaml(path, ImuNoise())
    path.write_text(f"{path.read_text()}{line}\n")
    with pytest.raises(KalibrFormatError, match=f"^{path}: {key}: IMU grade"):
        read_imu_grade(path)


def found_gyro_error(estimate, covariance, prior, statistic=1.0, threshold=22.5):
    sensitivity = np.random.default_rng(3).normal(size=(4, 6))
    return ImuModelError(GYRO, np.asarray(estimate), covariance, statistic, threshold, sensitivity, prior)


def test_the_grade_enters_as_the_posterior_of_the_terms_given_what_the_data_show():
    """Below the evidence threshold the spread is the grade's posterior given the data's estimate: the information
    form's mean (Sigma_g^-1 + Sigma^-1)^-1 Sigma^-1 theta and covariance, computed independently here."""
    rng = np.random.default_rng(7)
    L = rng.normal(size=(6, 6)) * 0.004
    data_covariance = L @ L.T + 1e-6 * np.eye(6)
    estimate = rng.normal(size=6) * 0.003
    prior = GYRO.prior(imu_grade("industrial"))
    found = found_gyro_error(estimate, data_covariance, prior)
    posterior = np.linalg.inv(np.linalg.inv(prior) + np.linalg.inv(data_covariance))
    mean = posterior @ np.linalg.solve(data_covariance, estimate)
    np.testing.assert_allclose(found.spread(), np.outer(mean, mean) + posterior, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(found.considered(), found.sensitivity @ found.spread() @ found.sensitivity.T)
    # what the data do not see at all: the grade's own spread; a calibrated IMU: nothing
    blind = found_gyro_error(np.zeros(6), 1e6 * np.eye(6), prior)
    np.testing.assert_allclose(blind.spread(), prior, rtol=1e-6)
    assert not np.any(found_gyro_error(estimate, data_covariance, np.zeros((6, 6))).spread())


def test_where_the_data_show_the_terms_their_own_estimate_counts_whatever_the_grade():
    estimate, covariance = np.full(6, 0.004), 1e-7 * np.eye(6)
    for prior in (np.zeros((6, 6)), GYRO.prior(imu_grade("consumer"))):
        found = found_gyro_error(estimate, covariance, prior, statistic=900.0)
        np.testing.assert_allclose(found.spread(), np.outer(estimate, estimate) + covariance)
