"""State estimation of the object to pick: back-projection to the belt plane and the paper's
constant-velocity Kalman tracker (belt or image frame)."""

from stackpick_sim.estimation.backproject import (
    backproject_at_depth,
    backproject_to_plane,
    pixel_rays,
    plane_backprojection_jacobian,
    project_to_pixels,
    transfer_via_plane,
)
from stackpick_sim.estimation.kalman import (
    PRIOR_RESTART,
    ConstantVelocityTracker,
    Prediction,
    TrackerConfig,
    UpdateResult,
    belt_accel_psd,
    process_noise,
    relaxed_transition,
    transition,
)
from stackpick_sim.exceptions import EstimationError

__all__ = [
    "PRIOR_RESTART",
    "ConstantVelocityTracker",
    "EstimationError",
    "Prediction",
    "TrackerConfig",
    "UpdateResult",
    "backproject_at_depth",
    "backproject_to_plane",
    "belt_accel_psd",
    "pixel_rays",
    "plane_backprojection_jacobian",
    "process_noise",
    "project_to_pixels",
    "relaxed_transition",
    "transfer_via_plane",
    "transition",
]
