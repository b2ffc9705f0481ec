"""The practitioner's sensors (sensor=practitioner): products drawn per episode, units around their datasheets."""

from dataclasses import replace

import numpy as np
import pytest
from configs import composed, env_parts

from vical.calib.tasks import CalibrationTask, run_task
from vical.config_checks import ConfigError
from vical.data.imu_grade import GRADES
from vical.env.calibration import CalibrationEnv
from vical.env.settings import Workspace
from vical.env.workspace import board_in_sight, sight_range
from vical.geometry import CameraModel
from vical.sim import SimConfig
from vical.sim.adapters import RigFaults, SimRig
from vical.sim.camera import VisibilityRules
from vical.sim.products import Range
from vical.sim.sampling import SensorSampling, draw_product, mean_sensor, sample_sensor
from vical.sim.settings import BoardConfig

PRACTITIONER = composed("evaluate", ["sensor=practitioner"])["sensor"]
PAPER = composed("evaluate", ["sensor=paper"])["sensor"]
SEEDS = range(400)


def same_sensor(a, b) -> bool:
    return (a.camera == b.camera and np.array_equal(a.T_cam_imu, b.T_cam_imu) and a.time_offset == b.time_offset
            and a.imu_noise == b.imu_noise)  # fmt: skip


def products(**change) -> dict:
    cfg = {**PRACTITIONER, "products": {**PRACTITIONER["products"], **change}}
    return SensorSampling.from_config(cfg)


def test_a_range_draws_uniformly_and_a_log_range_its_logarithm():
    rng = np.random.default_rng(0)
    linear = np.array([Range(2.0, 4.0).draw(rng) for _ in range(4000)])
    log = np.array([Range(0.3, 10.0, log=True).draw(rng) for _ in range(4000)])
    assert linear.min() >= 2.0 and linear.max() <= 4.0
    assert abs(np.median(linear) - 3.0) < 0.05  # the uniform's median; a log draw's would be 2.83
    assert log.min() >= 0.3 and log.max() <= 10.0
    assert abs(np.median(log) - np.sqrt(0.3 * 10.0)) < 0.1  # the geometric mean 1.73; a uniform's would be 5.15
    assert abs(np.mean(np.log(log) < np.log(1.0)) - np.log(1 / 0.3) / np.log(10 / 0.3)) < 0.03


def test_without_products_every_episode_is_the_sensor_group_itself():
    paper = SensorSampling.from_config(PAPER)
    product = draw_product(paper, 123)
    assert product.sampling is paper and product.board is None
    assert same_sensor(product.datasheet, mean_sensor(paper))


def test_a_product_is_drawn_from_its_seed_and_its_units_around_its_datasheet():
    cfg = SensorSampling.from_config(PRACTITIONER)
    first, again = draw_product(cfg, 7), draw_product(cfg, 7)
    assert first == again
    assert first.sampling.products is None
    lens = first.sampling.camera
    choices = {c.distortion: c for c in cfg.products.lenses}
    assert lens.distortion in choices
    assert choices[lens.distortion].hfov.low <= lens.hfov.mean <= choices[lens.distortion].hfov.high
    assert lens.hfov.std == cfg.camera.hfov.std  # the unit's spread is the sensor group's
    scale = first.sampling.imu.gyro_noise / cfg.imu.gyro_noise
    assert 0.3 <= scale <= 10.0
    for name in ("accel_noise", "accel_random_walk", "gyro_random_walk"):  # one grade scales all four densities
        assert getattr(first.sampling.imu, name) == pytest.approx(scale * getattr(cfg.imu, name), rel=1e-12)
    datasheet = first.datasheet
    assert datasheet.camera.distortion == lens.distortion and datasheet.time_offset == 0.0
    assert datasheet.imu_noise == first.sampling.imu.kalibr_noise()
    units = [sample_sensor(first.sampling, np.random.default_rng(s)) for s in range(30)]
    hfovs = np.array([2 * np.arctan(u.camera.width / 2 / u.camera.fx) for u in units])
    if lens.distortion == "radtan":  # pinhole: fx from the hfov exactly
        assert abs(hfovs.mean() - lens.hfov.mean) < 4 * lens.hfov.std / np.sqrt(len(units))
    offsets = np.array([u.time_offset for u in units])
    assert 0.008 < offsets.std() < 0.024  # sensor.time_offset's 15 ms
    assert all(u.imu_noise == datasheet.imu_noise for u in units)


def test_the_families_are_drawn_as_often_as_their_weights_say():
    cfg = SensorSampling.from_config(PRACTITIONER)
    drawn = [draw_product(cfg, seed) for seed in SEEDS]
    lenses = {c.distortion: c.weight for c in cfg.products.lenses}
    boards = {c.kind: c.weight for c in cfg.products.boards}
    n = len(drawn)
    for counted, weights in (([p.sampling.camera.distortion for p in drawn], lenses),
                             ([p.board["kind"] for p in drawn], boards)):  # fmt: skip
        total = sum(weights.values())
        for name, weight in weights.items():
            share = weight / total
            assert abs(counted.count(name) / n - share) < 4 * np.sqrt(share * (1 - share) / n)
    squares = [p.board["square"] for p in drawn if p.board["kind"] == "aprilgrid"]
    assert 0.04 <= min(squares) < 0.045 and 0.105 < max(squares) <= 0.11


def test_the_unit_drawn_from_a_seed_does_not_depend_on_its_product_draw():
    """A product changes what it draws and nothing after it: a pinhole product's unit draws the extrinsic and the
    time offset the seed gives without products (the same number of draws before them: hfov, k1, k2)."""
    cfg = SensorSampling.from_config(PRACTITIONER)
    seed = next(s for s in SEEDS if draw_product(cfg, s).sampling.camera.distortion == "radtan")
    unit = sample_sensor(draw_product(cfg, seed).sampling, np.random.default_rng(seed))
    plain = sample_sensor(replace(cfg, products=None), np.random.default_rng(seed))
    assert unit.camera != plain.camera  # another nominal field of view
    np.testing.assert_array_equal(unit.T_cam_imu, plain.T_cam_imu)
    assert unit.time_offset == plain.time_offset


GRADED = composed("evaluate", ["sensor=practitioner_graded"])["sensor"]


def test_an_imu_grade_is_drawn_per_product_its_units_terms_from_it_and_its_datasheet_declares_it():
    plain, graded = SensorSampling.from_config(PRACTITIONER), SensorSampling.from_config(GRADED)
    drawn = [draw_product(graded, seed) for seed in SEEDS]
    assert graded.products.lenses == plain.products.lenses and graded.products.boards == plain.products.boards
    for name, weight in (("industrial", 0.4), ("consumer", 0.4), ("calibrated", 0.2)):
        share = sum(p.datasheet.imu_grade == GRADES[name] for p in drawn) / len(drawn)
        assert abs(share - weight) < 4 * np.sqrt(weight * (1 - weight) / len(drawn))
    for seed in SEEDS[:40]:  # the grade is drawn last: the rest of the product is the one drawn without it
        product, before = draw_product(graded, seed), draw_product(plain, seed)
        assert product.board == before.board and product.sampling.camera == before.sampling.camera
        assert product.sampling.imu.grade() == product.datasheet.imu_grade
    consumer = [p for p in drawn if p.datasheet.imu_grade == GRADES["consumer"]][:200]
    scales = np.array([sample_sensor(p.sampling, np.random.default_rng(k)).imu_intrinsics.vector()[:3]
                       for k, p in enumerate(consumer)])  # fmt: skip
    assert np.std(scales) == pytest.approx(GRADES["consumer"].accel_scale, rel=0.15)
    unit = sample_sensor(consumer[0].sampling, np.random.default_rng(0)).imu_intrinsics
    np.testing.assert_array_equal(unit.C_gyro_i, np.eye(3))  # no grade term for it: not drawn
    assert not np.allclose(unit.M_gyro, np.eye(3))
    calibrated = next(p for p in drawn if p.datasheet.imu_grade.perfect)
    assert sample_sensor(calibrated.sampling, np.random.default_rng(0)).imu_intrinsics.is_identity()


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"imu_grades": [{"grade": "tactical"}]}, r"sensor\.products\.imu_grades\[0\]\.grade"),
        ({"imu_noise_scale": {"low": 2.0, "high": 1.0}}, r"sensor\.products\.imu_noise_scale\.high"),
        ({"imu_noise_scale": {"low": 0.0, "high": 1.0, "log": True}}, r"sensor\.products\.imu_noise_scale\.low"),
        (
            {"lenses": [{"distortion": "radtan", "hfov": {"low": 0.8, "high": 3.5}}]},
            r"sensor\.products\.lenses\[0\]\.hfov\.high",
        ),
        (
            {"lenses": [{"distortion": "fisheye", "hfov": {"low": 0.8, "high": 1.0}}]},
            r"sensor\.products\.lenses\[0\]\.distortion",
        ),
        (
            {"lenses": [{"distortion": "radtan", "hfov": {"low": 0.8, "high": 1.0}, "weight": 0.0}]},
            r"sensor\.products\.lenses\[\]\.weight",
        ),
        (
            {"boards": [{"kind": "aprilgrid", "rows": 6, "cols": 6, "square": {"low": 0.001, "high": 0.1}}]},
            r"sensor\.products\.boards\[0\]\.square",
        ),
        (
            {"boards": [{"kind": "charuco", "rows": 6, "cols": 6, "square": {"low": 0.04, "high": 0.1}}]},
            r"sensor\.products\.boards\[0\]\.kind",
        ),
        (
            {
                "boards": [
                    {"kind": "aprilgrid", "rows": 6, "cols": 6, "square": {"low": 0.04, "high": 0.1}, "weight": -1.0}
                ]
            },
            r"sensor\.products\.boards\[0\]\.weight",
        ),
        (
            {"boards": [{"kind": "aprilgrid", "rows": 6, "square": {"low": 0.04, "high": 0.1}}]},
            r"sensor\.products\.boards\[0\]",
        ),
    ],
)
def test_an_empty_or_unphysical_distribution_is_one_line_naming_its_key(change, key):
    with pytest.raises(ConfigError, match=key) as err:
        products(**change)
    assert "\n" not in str(err.value)


def test_the_env_stands_each_episode_before_its_products_board_and_guesses_its_datasheet():
    sim, sensor, task, mdp = env_parts("joint", "practitioner", "sensor=practitioner", "env=information",
                                       "task.camera_model=sensor")  # fmt: skip
    env = CalibrationEnv(sim, sensor, task, **mdp)
    try:
        seen = set()
        for seed in range(40000, 40020):
            env.reset(seed=seed)
            board = env.product.board
            if board["kind"] in seen:
                continue
            seen.add(board["kind"])
            assert env._usable(env.product)  # its camera detects its board somewhere in the workspace
            assert env.sim.cfg.board.square == board["square"] and env.target == env.sim.cfg.board.target
            for _ in range(3):
                env.step(np.array([0.0, 0.3, 0.2, 0.3, 0.1, -0.1]))
            recording = env.recording()
            assert recording.target == env.target
            assert max(int(ids.max()) for ids in recording.frames.ids if len(ids)) < env.target.num_points
            guess = env.state.information.guess
            assert guess.camera == env.product.datasheet.camera != env.truth.camera
            assert guess.time_offset == 0.0 != env.truth.time_offset
        assert seen == {"aprilgrid", "checkerboard"}
        env.reset(seed=40000)
        again = env.truth
        env.reset(seed=40001)
        env.reset(seed=40000)
        assert env.truth.camera == again.camera and env.truth.time_offset == again.time_offset
    finally:
        env.close()


def test_a_simulated_rig_holds_the_product_and_board_the_env_draws_for_the_same_seed():
    sim, sensor, task, mdp = env_parts("joint", "practitioner", "sensor=practitioner")
    rig = SimRig(SimConfig.from_mapping(sim), SensorSampling.from_config(sensor), 40002, True, RigFaults())
    env = CalibrationEnv(sim, sensor, task, **mdp)
    try:
        env.reset(seed=40002)
        assert rig.target == env.target and rig.target != SimConfig.from_mapping(sim).board.target
        assert rig.truth.camera == env.truth.camera and same_sensor(rig.datasheet, env.product.datasheet)
    finally:
        env.close()
        rig.close()


def test_task_camera_model_sensor_calibrates_each_recording_with_its_own_lens_model():
    """A wide-angle product's episode: the joint solve estimates its double-sphere lens and recovers its truth."""
    sim, sensor, task, mdp = env_parts("joint", "practitioner", "sensor=practitioner", "task.camera_model=sensor")
    env = CalibrationEnv(sim, sensor, task, **mdp)
    try:
        seed = 40000
        while env.reset(seed=seed) and not (
            env.product.sampling.camera.distortion == "ds" and env.recording().frames.num_detections.max() > 0
        ):
            seed += 1
        for action in np.tile([[0.1, 0.4, 0.3, 0.5, 0.2, -0.15], [-0.1, -0.4, -0.3, -0.5, -0.2, 0.15]], (6, 1)):
            env.step(action)
        recording = env.recording()
    finally:
        env.close()
    task = CalibrationTask.from_config(task)
    assert task.model_of(recording) == "ds"
    outcome = run_task(task, recording)
    assert outcome.result.camera.distortion == "ds"
    assert outcome.errors.rotation_deg < 0.3 and outcome.errors.time_offset_ms < 1.0
    with pytest.raises(ConfigError, match=r"task\.camera_model=sensor"):
        task.model_of(replace(recording, truth=None))


def test_a_board_is_in_sight_where_its_tags_reach_the_detectors_smallest_size():
    """A 6 x 6 aprilgrid, fronto-parallel at the workspace's nearest 0.47 m: tags of f * tag / d >= 32 px count."""
    camera = CameraModel.from_hfov(1.8, 640, 480, [0.0, 0.0, 0.0, 0.0], "radtan")
    smallest = VisibilityRules().min_tag_px * 0.47 / camera.fx  # [m] 59 mm with this 103 deg lens
    for factor, seen in ((1.05, True), (0.95, False)):
        board = BoardConfig(kind="aprilgrid", rows=6, cols=6, square=factor * smallest, distance=0.72)
        assert board_in_sight(board.target, camera, 0.47, 0.97) is seen
    near, far = sight_range(0.72, Workspace(frame="board", position=(0.25, 0.35, 0.2)))
    assert (near, far) == pytest.approx((0.47, 0.97))
