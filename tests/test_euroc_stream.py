"""EuRoC folders written while the data arrives: exact round trip, and readable after a kill -9 at any moment or a
disk that stops taking data."""

import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from stopped_collections import file_size_limit

from vical.data import ImuNoise, ImuSamples, Target
from vical.io.euroc import EurocStreamWriter, read_euroc

TARGET = Target.checkerboard(7, 6, 0.04)
SIZE = (64, 48)


def imu_batch(k: int, n: int = 20) -> ImuSamples:
    """IMU samples k*n .. k*n + n - 1 at 200 Hz with values that are exact only at full precision."""
    rng = np.random.default_rng(k)
    t = (np.arange(k * n, (k + 1) * n) * 5_000_000).astype(np.int64)
    return ImuSamples(t, rng.normal(0, 0.3, (n, 3)), rng.normal(0, 1.0, (n, 3)) + [0, 0, 9.81])


def frame(k: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Frame k at 20 Hz: a random image and, every other frame, three detected corners."""
    rng = np.random.default_rng(100 + k)
    ids = np.array([0, 5, 17]) if k % 2 == 0 else np.zeros(0, np.int64)
    return k * 50_000_000, rng.integers(0, 256, SIZE[::-1], dtype=np.uint8), rng.uniform(0, 40, (len(ids), 2)), ids


def test_a_streamed_folder_reads_back_exactly(tmp_path):
    noise = ImuNoise()
    with EurocStreamWriter(tmp_path / "rec", SIZE, 20.0, 200.0, noise) as writer:
        for k in range(6):
            writer.add_imu(imu_batch(k))
            writer.add_frame(*frame(k))
    rec = read_euroc(tmp_path / "rec", TARGET)
    batches = [imu_batch(k) for k in range(6)]
    imu = ImuSamples.concatenate(batches)
    np.testing.assert_array_equal(rec.imu.t, imu.t)
    np.testing.assert_array_equal(rec.imu.gyro, imu.gyro)
    np.testing.assert_array_equal(rec.imu.accel, imu.accel)
    assert len(rec.frames) == 6
    for k in range(6):
        t, image, corners, ids = frame(k)
        assert rec.frames.t[k] == t
        np.testing.assert_array_equal(rec.frames.images[k], image)
        np.testing.assert_array_equal(rec.frames.ids[k], ids)
        np.testing.assert_array_equal(rec.frames.corners[k], corners)
    sensor = (tmp_path / "rec" / "mav0" / "imu0" / "sensor.yaml").read_text()
    assert f"gyroscope_noise_density: {noise.gyro_noise_density}" in sensor


def test_an_existing_folder_and_a_wrong_image_size_are_refused(tmp_path):
    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "notes.txt").write_text("a previous recording")
    with pytest.raises(FileExistsError, match="already exists"):
        EurocStreamWriter(tmp_path / "rec", SIZE, 20.0, 200.0)
    assert (tmp_path / "rec" / "notes.txt").is_file()
    wrong = r"48 x 64 px image, but the recording is \(64, 48\)"
    with EurocStreamWriter(tmp_path / "new", SIZE, 20.0, 200.0) as writer, pytest.raises(ValueError, match=wrong):
        writer.add_frame(0, np.zeros((64, 48), np.uint8), np.zeros((0, 2)), np.zeros(0))


WRITER_LOOP = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, {tests!r})
    from test_euroc_stream import SIZE, frame, imu_batch
    from vical.io.euroc import EurocStreamWriter
    writer = EurocStreamWriter({path!r}, SIZE, 20.0, 200.0)
    k = 0
    while True:
        writer.add_imu(imu_batch(k))
        writer.add_frame(*frame(k))
        k += 1
    """
)


@pytest.mark.integration
@pytest.mark.parametrize("wait", [0.6, 1.3])
def test_a_kill_at_any_moment_leaves_a_readable_folder(tmp_path, wait):
    path = tmp_path / "rec"
    script = WRITER_LOOP.format(tests=str(Path(__file__).parent), path=str(path))
    writer = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 60
        listed = path / "mav0" / "cam0" / "data.csv"
        while (not listed.is_file() or listed.read_text().count("\n") < 5) and time.monotonic() < deadline:
            assert writer.poll() is None, "the writer died on its own"
            time.sleep(0.05)
        time.sleep(wait)
    finally:
        writer.send_signal(signal.SIGKILL)
        writer.wait()
    rec = read_euroc(path, TARGET)
    n = len(rec.frames)
    assert n >= 5
    for k in range(n):  # every listed frame is whole, with its detections (the last may have lost them)
        t, image, corners, _ = frame(k)
        assert rec.frames.t[k] == t
        np.testing.assert_array_equal(rec.frames.images[k], image)
        if k < n - 1:
            np.testing.assert_array_equal(rec.frames.corners[k], corners)
    assert len(rec.imu) % 20 == 0 and len(rec.imu) >= 20 * n  # IMU batches whole, none lost before the frames
    np.testing.assert_array_equal(rec.imu.t, np.arange(len(rec.imu)) * 5_000_000)


def test_a_disk_that_stops_taking_data_leaves_whole_lines_and_one_error(tmp_path):
    """The writer's files may grow to 40 kB (the IMU's CSV reaches it first, at its 17th batch): the write that
    crosses the limit is cut back, the error says what happened, and the folder reads back whole."""
    path = tmp_path / "rec"
    script = WRITER_LOOP.format(tests=str(Path(__file__).parent), path=str(path))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60,
                          preexec_fn=file_size_limit(40_000))  # fmt: skip
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 1
    assert last.startswith(f"vical.io.errors.RecordingWriteError: {path}: the disk took no more (")
    assert "File too large; is it full?); the " in last and " frames and " in last
    imu_csv = (path / "mav0" / "imu0" / "data.csv").read_bytes()
    assert 35_000 < len(imu_csv) <= 40_000 and imu_csv.endswith(b"\n")
    rec = read_euroc(path, TARGET)
    n = len(rec.frames)
    assert n >= 10 and len(rec.imu) >= 20 * n and len(rec.imu) % 20 == 0
    assert f"the {n} frames and {len(rec.imu)} IMU samples before are whole" in last
    for k in range(n):
        _, image, corners, _ = frame(k)
        np.testing.assert_array_equal(rec.frames.images[k], image)
        np.testing.assert_array_equal(rec.frames.corners[k], corners)
    np.testing.assert_array_equal(rec.imu.t, np.arange(len(rec.imu)) * 5_000_000)
