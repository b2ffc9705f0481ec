"""TensorBoard logging of a resumed run: its event file is read after the interrupted run's, however soon the run
resumes, so the purge on resume keeps each step once.

TensorBoard reads a folder's event files in the order of their names, ``events.out.tfevents.<second>.<host>.
<pid>.<counter>``: two files of one second and one process order by their counters as text, so counter 10 comes
before counter 9 (CI: a run resumed within the second its first writer was made, the counter going from 9 to 10;
the resumed run's events were read first and its purge dropped the first run's steps 50-300).
"""

from __future__ import annotations

import time
from pathlib import Path

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from vical.rl.logger import TrainLogger


def steps(log_dir: Path, tag: str) -> list[int]:
    return [e.step for e in EventAccumulator(str(log_dir), size_guidance={"scalars": 0}).Reload().Scalars(tag)]


def test_a_run_resumed_within_the_second_of_its_first_writer_keeps_every_step_once(tmp_path, monkeypatch):
    import tensorboard.summary.writer.event_file_writer as event_file_writer

    first = TrainLogger(tmp_path, ())
    for step in range(10, 60, 10):
        first.scalars({"charts/x": float(step)}, step)
    first.close()
    # As if the first writer had been made in the second the run resumes in (the next one: no wait in the test
    # can make it the same), with counter 9, and the resumed writer got counter 10.
    (made,) = tmp_path.iterdir()
    head, _, host, pid, _ = made.name.rsplit(".", 4)
    made.rename(tmp_path / f"{head}.{int(time.time()) + 1:010d}.{host}.{pid}.9")
    monkeypatch.setattr(event_file_writer._global_uid, "get", lambda: 10)
    resumed = TrainLogger(tmp_path, (), purge_step=31)  # a checkpoint at step 30: steps 31-50 are logged anew
    for step in range(40, 80, 10):
        resumed.scalars({"charts/x": float(step)}, step)
    resumed.close()
    assert steps(tmp_path, "charts/x") == [10, 20, 30, 40, 50, 60, 70]
