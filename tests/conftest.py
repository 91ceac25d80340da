"""Test-suite set-up: headless rendering before any test module imports MuJoCo."""

import os

# MuJoCo picks its GL backend at first import; test modules import mujoco directly.
os.environ.setdefault("MUJOCO_GL", "egl")
