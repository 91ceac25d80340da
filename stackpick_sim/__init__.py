"""stackpick-sim: a MuJoCo digital twin of a vision-guided cell picking the top object off
stacks of overlapped cylinders on a moving conveyor."""

import os
import sys

# Headless by default: MuJoCo picks its GL backend when it is first imported, and this
# package renders offscreen on machines without a display or GPU (Mesa's EGL). Remember
# whether MuJoCo chose before us, so that a rendering failure can say so.
MUJOCO_IMPORTED_FIRST = "mujoco" in sys.modules and "MUJOCO_GL" not in os.environ
os.environ.setdefault("MUJOCO_GL", "egl")
# OpenCV's codecs refuse a declared size above this before allocating (read when cv2 loads);
# it backs up stackpick_sim.image_io's own header check (4096 x 4096 px).
os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(4096 * 4096))

from stackpick_sim.exceptions import (  # noqa: E402 - after the GL default
    ConfigError,
    ImageError,
    ModelError,
    RenderError,
    SceneGenerationError,
    StackpickError,
)
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle, tilt_angles  # noqa: E402

__all__ = [
    "CameraIntrinsics",
    "ConfigError",
    "Ellipse",
    "ImageError",
    "ModelError",
    "RenderError",
    "SceneGenerationError",
    "StackpickError",
    "project_circle",
    "tilt_angles",
]
