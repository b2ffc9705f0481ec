"""The composed config of every app and every experiment is pinned: tests/data/composed/<case>.json.

A change of a default, of a group's file or of an experiment shows here as the settings it changes in what
the command line runs (every experiment and every shipped policy ran with these). When a change is intended,
write the snapshots anew and commit them with it:

    python tests/test_composed_configs.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
SNAPSHOTS = Path(__file__).resolve().parent / "data" / "composed"
APPS = ("train", "evaluate", "record", "collect", "guide")
# train_*.yaml configure vical-train, the others vical-evaluate (as tests/test_config_compose.py composes them).
EXPERIMENTS = sorted(f.stem for f in (CONF / "experiment").glob("*.yaml"))
CASES = [*APPS, *(f"{'train' if e.startswith('train_') else 'evaluate'}+{e}" for e in EXPERIMENTS)]
REGENERATE = "python tests/test_composed_configs.py"


def composed(case: str) -> dict[str, Any]:
    """The config ``case`` (``<app>`` or ``<app>+<experiment>``) composes, resolved; ``${now:...}`` stays as written."""
    app, _, experiment = case.partition("+")
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name=app, overrides=[f"+experiment={experiment}"] if experiment else [])
    raw = OmegaConf.to_container(cfg, resolve=False)
    resolved = OmegaConf.to_container(cfg, resolve=True)
    # The output directories' time stamps are the only values that depend on when the config is composed.
    clock = {key: value for key, value in raw.items() if isinstance(value, str) and "${now:" in value}
    return {**resolved, **clock}


def _differences(old: Any, new: Any, key: str = "") -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        found = []
        for k in sorted(set(old) | set(new), key=str):
            found += _differences(old.get(k, "<missing>"), new.get(k, "<missing>"), f"{key}.{k}" if key else k)
        return found
    return [] if old == new and type(old) is type(new) else [f"{key}: {old!r} -> {new!r}"]


@pytest.mark.parametrize("case", CASES)
def test_the_composed_config_is_the_pinned_one(case):
    path = SNAPSHOTS / f"{case}.json"
    assert path.is_file(), f"{path.relative_to(ROOT)} is missing: {REGENERATE}"
    changed = _differences(json.loads(path.read_text()), composed(case))
    assert not changed, (
        f"the composed config of {case} changed (what the command line runs with): {'; '.join(changed)}. "
        f"If that is intended, write the snapshots anew ({REGENERATE}) and commit them with the change."
    )


def test_every_snapshot_is_a_case():
    assert sorted(p.stem for p in SNAPSHOTS.glob("*.json")) == sorted(CASES)


def write() -> None:
    SNAPSHOTS.mkdir(parents=True, exist_ok=True)
    for stale in SNAPSHOTS.glob("*.json"):
        stale.unlink()
    for case in CASES:
        (SNAPSHOTS / f"{case}.json").write_text(json.dumps(composed(case), indent=1, sort_keys=True) + "\n")
        print(SNAPSHOTS.relative_to(ROOT) / f"{case}.json")


if __name__ == "__main__":
    sys.exit(write())
