"""Eye-in-hand visual servoing: interaction matrices, twist transforms, the servo law and its
execution through mink within joint limits."""

from stackpick_sim.control.execution import JointVelocityExecutor, JointVelocityTask
from stackpick_sim.control.eye_in_hand import EyeInHand
from stackpick_sim.control.interaction import (
    circle_pose_features,
    circle_pose_interaction,
    desired_circle_pose_features,
    ellipse_interaction,
    ellipse_moments,
    log_depth_interaction,
    normal_interaction,
    plane_coefficients,
    point_interaction,
)
from stackpick_sim.control.servo import (
    AdaptiveGain,
    ServoConfig,
    damped_pinv,
    saturated_servo_velocity,
    servo_velocity,
    target_feature_rate,
)
from stackpick_sim.control.twist import (
    invert_transform,
    make_transform,
    rotate_twist_matrix,
    skew,
    twist_exp,
    velocity_twist_matrix,
)
from stackpick_sim.exceptions import ControlError

__all__ = [
    "AdaptiveGain",
    "ControlError",
    "EyeInHand",
    "JointVelocityExecutor",
    "JointVelocityTask",
    "ServoConfig",
    "circle_pose_features",
    "circle_pose_interaction",
    "damped_pinv",
    "desired_circle_pose_features",
    "ellipse_interaction",
    "ellipse_moments",
    "invert_transform",
    "log_depth_interaction",
    "make_transform",
    "normal_interaction",
    "plane_coefficients",
    "point_interaction",
    "rotate_twist_matrix",
    "saturated_servo_velocity",
    "servo_velocity",
    "skew",
    "target_feature_rate",
    "twist_exp",
    "velocity_twist_matrix",
]
