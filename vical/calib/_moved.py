"""Module paths of ``vical.calib`` from before it was split by stage, kept importable.

``import vical.calib.intrinsics`` (or ``from vical.calib.aprilgrid import ...``) in code, pickles and notebooks
written before the split gives the module at its new home (the same module object, so a patch through either
path patches both).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

MOVED = {
    "calibrate": "solve.pipeline",
    "aprilgrid": "detection.aprilgrid",
    "board_size": "detection.board_size",
    "allan": "noise.allan",
    "allan_plot": "noise.allan_plot",
    "report_figures": "report.figures",
    **{
        name: f"solve.{name}"
        for name in (
            "pipeline", "intrinsics", "visual_inertial", "corner_factors", "initialization", "observations",
            "outliers", "rig", "solver", "time_alignment", "imu_integration", "imu_intrinsics", "robust_covariance",
            "variance", "uncertainty", "checks", "nominal", "model_fit", "plausibility",
        )
    },
}  # fmt: skip


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``vical.calib.<old name>`` and loads it as the module at its new path."""

    PREFIX = "vical.calib."

    def find_spec(self, fullname, path=None, target=None):
        if fullname.startswith(self.PREFIX) and fullname[len(self.PREFIX) :] in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        return importlib.import_module(self.PREFIX + MOVED[spec.name[len(self.PREFIX) :]])

    def exec_module(self, module) -> None:
        """Nothing to run: the module was imported at its new path."""


def install() -> None:
    """Put the finder on ``sys.meta_path`` once (after the regular finders: a module that exists wins)."""
    if not any(isinstance(f, MovedModules) for f in sys.meta_path):
        sys.meta_path.append(MovedModules())
