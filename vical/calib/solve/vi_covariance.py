"""The camera-IMU solve's uncertainty: the marginal covariance of its parameters, widened by the cluster-robust
one (``vical.calib.solve.robust_covariance``), and the warnings about the noise, the span and the gaps of the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from vical.calib.result import UnmodelledImuTerms
from vical.calib.solve.imu_model_error import ImuModelError, imu_model_errors
from vical.calib.solve.robust_covariance import LinearSystem, sandwich_covariances, widen
from vical.calib.solve.solver import covariance_or_unobservable, determined
from vical.calib.solve.vi_graph import ViGraph, variance_scale
from vical.calib.solve.vi_problem import (
    GAP_WARNING_FACTOR,
    I_KEY,
    IMU_NOISE_WARNING,
    MIN_GAP_WARNING,
    WIDENING_WARNING,
    ViProblem,
    state_key,
)
from vical.data import ImuNoise
from vical.geometry import skew


def imu_noise_warning(scale: float, declared: ImuNoise, weighting: str) -> list[str]:
    """A note when the IMU's residuals show a noise ``scale`` x the ``declared`` densities, with the imu.yaml values
    that would match them."""
    if 1 / IMU_NOISE_WARNING <= scale <= IMU_NOISE_WARNING:
        return []
    side = "larger; 5-15x is common for real IMUs" if scale > 1 else "smaller: inflated densities are common"
    kept = weighting == "declared" or (weighting == "declared-or-less" and scale > 1)
    how = (
        "the estimate weighs the IMU by the declared densities, its uncertainty by the measured noise"
        if kept
        else "the solve weighted the IMU by its measured noise and the uncertainty uses it"
    )
    match = declared.scaled(scale)
    return [
        f"the IMU residuals show a noise {scale:.3g}x the declared densities ({side}); {how}. imu.yaml values that "
        f"match the residuals{' (judged at the declared weights: a large excess reads low)' if kept else ''}: "
        f"gyroscope_noise_density {match.gyro_noise_density:.3g}, accelerometer_noise_density "
        f"{match.accel_noise_density:.3g}, gyroscope_random_walk {match.gyro_random_walk:.3g}, "
        f"accelerometer_random_walk {match.accel_random_walk:.3g}"
    ]


# ---------------------------------------------------------------------------------------- data notes
def span_warnings(problem: ViProblem, g: ViGraph) -> list[str]:
    """A note when frames with a target pose fell outside the IMU's time span and got no state."""
    outside = len(problem.frame_ids) - len(g.states)
    if outside == 0:
        return []
    frames = problem.frame_times
    return [
        f"{outside} frames with a target pose lie outside the IMU samples' time span "
        f"({problem.t_imu[0]:.3f}..{problem.t_imu[-1]:.3f} s after the recording start; frames span "
        f"{frames[0]:.3f}..{frames[-1]:.3f} s) and were dropped"
    ]


def gap_warnings(state_times: np.ndarray) -> list[str]:
    """Notes on stretches without usable target views; the IMU factor across each one bridges it."""
    if len(state_times) < 2:
        return []
    dt = np.diff(state_times)
    limit = max(MIN_GAP_WARNING, GAP_WARNING_FACTOR * float(np.median(dt)))
    return [
        f"no usable target view for {dt[n]:.2f} s ({state_times[n]:.2f}..{state_times[n + 1]:.2f} s after the "
        "recording start, IMU clock): one IMU factor bridges the gap, with less accuracy"
        for n in np.flatnonzero(dt > limit)
    ]


# ---------------------------------------------------------------------------------------- uncertainty
def _extrinsic_jacobian(T_cam_imu: np.ndarray) -> np.ndarray:
    """(6, 6) map from the tangent of ``E = T_imu_cam`` to [rotation error of R_cam_imu, t_cam_imu]."""
    J = np.zeros((6, 6))
    J[:3, :3] = -np.eye(3)
    J[3:, :3] = skew(T_cam_imu[:3, 3])
    J[3:, 3:] = -np.eye(3)
    return J


def _clusters(g: ViGraph, num_factors: int) -> np.ndarray:
    """The time window of every factor of the graph; -1 for the priors.

    IMU factor n joins states n and n + 1 (window of state n); a corner factor, its frame's state's.
    """
    states = g.factor_states[:num_factors]
    return np.where(states >= 0, g.state_windows[np.maximum(states, 0)], -1)


@dataclass
class ViMarginals:
    """The joint covariances of every camera's variables, the first bias and the IMU intrinsics, computed once for
    all cameras of a rig (one linearisation, one elimination, one sparse factorisation).

    ``model``: the noise model's (GTSAM's marginals: NaN where the data leave a direction free); ``scaled``: under
    the measured noise levels (None with a singular information); ``robust``: the cluster-robust one or None.
    """

    columns: dict[int, np.ndarray]  # each key's rows and columns in the matrices
    model: np.ndarray
    scaled: np.ndarray | None
    robust: np.ndarray | None
    # the gyro's and accelerometer's scales and misalignments the residuals show (imu_model_error)
    imu_model: list[ImuModelError] = field(default_factory=list)

    def block(self, keys: list[int]) -> tuple[np.ndarray, np.ndarray | None, list[UnmodelledImuTerms]]:
        """The keys' covariance (the measured noise levels' where finite, else the model's), robust one, and what
        the IMU's unmodelled scales and misalignments add, per sensor (``ImuModelError.considered``)."""
        index = np.concatenate([self.columns[k] for k in keys])
        model = self.model[np.ix_(index, index)]
        if self.scaled is not None and np.all(np.isfinite(model)):
            model = self.scaled[np.ix_(index, index)]
        robust = None if self.robust is None else self.robust[np.ix_(index, index)]
        terms = [UnmodelledImuTerms(f.sensor.name, f.sensitivity[index], f.spread()) for f in self.imu_model]
        return model, robust, terms


def _camera_keys(index: int, joint: bool, fixed_offset: bool, rolling: bool) -> list[int]:
    return (
        ([state_key("k", index)] if joint else [])
        + [state_key("e", index)]
        + ([] if fixed_offset else [state_key("d", index)])
        + ([state_key("l", index)] if rolling else [])
    )


def solution_marginals(
    problem: ViProblem, g: ViGraph, values: gtsam.Values, joint: bool, estimated_imu: bool
) -> ViMarginals:
    fixed, rolling = not problem.options.estimate_time_offset, problem.options.rolling_shutter
    keys = [k for index in range(len(problem.others) + 1) for k in _camera_keys(index, joint, fixed, rolling)]
    keys += [state_key("b", 0)] + ([I_KEY] if estimated_imu else [])
    linear = g.graph.linearize(values)
    system = LinearSystem(linear, values, _clusters(g, linear.size()), variance_scale(problem, g, linear.size()))
    found = sandwich_covariances(system, keys)
    # The sparse factorisation's covariance serves where it has no free direction; else the elimination tells the
    # free directions apart (NaN) from the determined ones.
    model = found.model if found is not None and determined(found.model) else None
    if model is None:
        model = covariance_or_unobservable(linear, values, keys)
    zero = values.zeroVectors()
    sizes = [zero.at(k).size for k in keys]
    starts = np.cumsum([0, *sizes])
    columns = {k: np.arange(starts[n], starts[n + 1]) for n, k in enumerate(keys)}
    imu_model = []
    if not estimated_imu:  # the scale-misalignment model estimates them
        imu = (problem.t_imu, problem.gyro, problem.accel)
        imu_model = imu_model_errors(system, linear, g.imu_factors, g.state_times, imu, keys, problem.options.imu_grade)
    scaled, robust = (None, None) if found is None else (found.scaled, found.robust)
    return ViMarginals(columns, model, scaled, robust, imu_model)


def parameter_covariance(
    marginals: ViMarginals,
    values: gtsam.Values,
    T_cam_imu: np.ndarray,
    joint: bool,
    fixed_offset: bool,
    index: int = 0,
    imu_theta: np.ndarray | None = None,
    rows: int | None = None,
    centre: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, list[UnmodelledImuTerms]]:
    """(P, P) covariance in the order of the result's parameter names, its widening (P,) over the noise model's, and
    what the IMU's unmodelled scales and misalignments add to it, per sensor, in those parameters.

    Of camera ``index``'s variables (0: the first camera's), its line delay when it has ``rows`` (its image height:
    the graph's variable is the readout, the line delay times the rows), the first bias and, with ``imu_theta``
    (the estimated IMU intrinsics), those. The time offset (row 0's) is the graph's (``centre``'s row's) less the
    readout up to that row. The covariance under the measured noise levels widened wherever the
    cluster-robust one (``vical.calib.solve.robust_covariance``) is larger, plus what the IMU's unmodelled scales and
    misalignments add (``vical.calib.solve.imu_model_error``; not part of the widening, which
    is the robust one's); a fixed time offset gets zero variance.
    """
    intrinsic_keys = [] if imu_theta is None else [I_KEY]
    keys = [*_camera_keys(index, joint, fixed_offset, rows is not None), state_key("b", 0), *intrinsic_keys]
    model, robust, terms = marginals.block(keys)
    cov = model if robust is None else widen(model, robust)
    camera_block = [np.eye(values.atVector(state_key("k", index)).size)] if joint else []
    blocks = camera_block + [_extrinsic_jacobian(T_cam_imu), _timing_block(fixed_offset, rows, centre), np.eye(6)]
    blocks += [] if imu_theta is None else [np.eye(len(imu_theta))]
    J = np.zeros((sum(b.shape[0] for b in blocks), cov.shape[0]))
    r = c = 0
    for b in blocks:
        J[r : r + b.shape[0], c : c + b.shape[1]] = b
        r, c = r + b.shape[0], c + b.shape[1]
    final, noise_model = J @ cov @ J.T, J @ model @ J.T
    with np.errstate(divide="ignore", invalid="ignore"):
        widening = np.sqrt(np.diag(final) / np.diag(noise_model))
    imu_terms = [replace(t, effect=J @ t.effect) for t in terms]
    considered = sum((t.covariance() for t in imu_terms), np.zeros_like(final))
    return final + considered, np.where(np.isfinite(widening), widening, 1.0), imu_terms


def _timing_block(fixed_offset: bool, rows: int | None, centre: float) -> np.ndarray:
    """Rows (time offset, [line delay]) from the columns (offset correction unless ``fixed_offset``, [readout])."""
    block = np.eye(1) if rows is None else np.array([[1.0, -centre], [0.0, 1.0 / rows]])
    return block[:, 1:] if fixed_offset else block


def widening_warning(names: list[str], widening: np.ndarray) -> list[str]:
    wide = [(n, w) for n, w in zip(names, widening, strict=True) if w > WIDENING_WARNING]
    if not wide:
        return []
    listing = ", ".join(f"{n} {w:.1f}x" for n, w in sorted(wide, key=lambda x: -x[1]))
    return [
        "the parameters move more with the data over time than the noise model explains (unmodelled effects such "
        f"as a rolling shutter or detector biases): their 1-sigma were widened to match ({listing})"
    ]
