"""stackpick-sim: a MuJoCo digital twin of a vision-guided cell picking the top object off
stacks of overlapped cylinders on a moving conveyor."""

from stackpick_sim.exceptions import (
    ConfigError,
    ImageError,
    ModelError,
    RenderError,
    SceneGenerationError,
    StackpickError,
)
from stackpick_sim.geometry import CameraIntrinsics, Ellipse, project_circle, tilt_angles

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
