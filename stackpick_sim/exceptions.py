"""The one exception hierarchy of stackpick-sim.

Every error the package raises on purpose derives from :class:`StackpickError`; the CLI
turns any of them into one line on stderr and exit code 2. A message says what was given
and what is allowed.
"""

from __future__ import annotations


class StackpickError(Exception):
    """Base class of every error raised on purpose by stackpick-sim."""


class ConfigError(StackpickError):
    """A scene config or override is malformed, unknown, of the wrong type or out of range."""


class ModelError(StackpickError):
    """An MJCF file is missing or fails to compile."""


class RenderError(StackpickError):
    """Offscreen rendering is unavailable (no EGL) or failed."""


class SceneGenerationError(StackpickError):
    """No valid stacked scene could be generated within the attempt budget."""


class ImageError(StackpickError):
    """An image given to the vision pipeline cannot be used (wrong dtype, shape, ...)."""


class IKError(StackpickError):
    """Inverse kinematics failed: unreachable target, bad input, or no convergence."""


class ControlError(StackpickError):
    """A servo input is malformed (wrong shape, unknown frame, non-positive depth, ...)."""


class EstimationError(StackpickError):
    """A tracker or back-projection input is malformed or geometrically impossible."""


class EpisodeError(StackpickError):
    """An episode cannot be set up or run as asked (bad settings, unknown failure reason)."""


class OutputError(StackpickError):
    """An output file cannot be written whole (no such directory, full disk, not a file...)."""
