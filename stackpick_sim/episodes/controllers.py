"""The built-in controller ``ibvs`` (:class:`stackpick_sim.pipeline.Controller`).

The approach moves the tool with a mink FrameTask (differential IK within the joint ranges
and speed limits) towards the pose on the face normal, ``standoff`` above the face predicted
``1 / episode.approach_gain`` s ahead; the servo, the descent and the grasp's hold follow the
image-Jacobian law on the 2.5-D circle-pose features
(:meth:`stackpick_sim.episodes.arm.ArmController.servo_rate`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.episodes.arm import ArmController, approach_pose
from stackpick_sim.pipeline import ControlGoal


class IbvsController:
    """``ibvs``: differential-IK approach, image-based visual servo after it."""

    name = "ibvs"

    def __init__(self, cfg: SceneConfig) -> None:
        self.approach_gain = cfg.episode.approach_gain

    def command(self, goal: ControlGoal, arm: ArmController) -> NDArray[np.float64]:
        """(6,) joint rates, rad/s, for this tick."""
        if goal.phase == "approach":
            assert goal.lead is not None, "the approach's goal carries the face ahead"
            pose = approach_pose(goal.lead, goal.standoff, arm.command_world_T_tool())
            return arm.pose_rate(pose, self.approach_gain, goal.dt)
        return arm.servo_rate(goal.target, goal.standoff, goal.standoff_rate, goal.dt)
