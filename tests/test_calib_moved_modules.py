"""The module paths of ``vical.calib`` from before its split by stage still import, as the modules at their new
homes (the same objects)."""

import importlib
import subprocess
import sys

import pytest

from vical.calib._moved import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_module_path_gives_the_module_at_its_new_home(old):
    assert importlib.import_module(f"vical.calib.{old}") is importlib.import_module(f"vical.calib.{MOVED[old]}")


def test_the_packages_that_took_a_modules_name_keep_its_names():
    from vical.calib.detection import detect_checkerboard
    from vical.calib.report import summary_table, write_report

    assert detect_checkerboard.__module__ == "vical.calib.detection.checkerboard"
    assert {summary_table.__module__, write_report.__module__} == {"vical.calib.report.writers"}


def test_old_paths_work_in_a_fresh_interpreter_and_a_missing_module_still_fails():
    code = (
        "from vical.calib.calibrate import calibrate_rig\n"
        "from vical.calib.visual_inertial import ViOptions\n"
        "import vical.calib.aprilgrid as a, vical.calib.detection.aprilgrid as b\n"
        "assert a is b and calibrate_rig.__module__ == 'vical.calib.solve.pipeline'\n"
        "try:\n    import vical.calib.no_such_module\nexcept ModuleNotFoundError:\n    print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
