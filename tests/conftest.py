"""Test-session set-up shared by every test module."""

import os
import warnings

import pytest

# MuJoCo picks its GL backend when first imported: offscreen EGL must be chosen before any test imports it.
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(autouse=True)
def _restore_warning_format(monkeypatch):
    """The apps' entry points print warnings in one line for the whole process; tests run them in-process."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)
