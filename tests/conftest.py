"""Test-session set-up shared by every test module."""

import os

# MuJoCo picks its GL backend when first imported: offscreen EGL must be chosen before any test imports it.
os.environ.setdefault("MUJOCO_GL", "egl")
