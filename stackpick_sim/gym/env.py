"""StackPick-v0: drive the arm through a pick, one camera frame per step.

* ``reset(seed=s)`` builds and settles the same pile as ``stackpick run --seeds s`` (same
  scene, same ``--set`` overrides) and runs the episode (look, detect, track) up to the first
  control tick of the approach: the agent is asked only when its action moves the arm.
* Observation (a dict): ``image`` the latest wrist-camera frame, (H, W, 3) uint8 RGB with the
  scene's noise; ``qpos``/``qvel`` the six arm joints' angles (rad) and rates (rad/s);
  ``phase`` the index of the phase in :data:`stackpick_sim.episodes.record.PHASES`.
* Action: (6,) joint velocity targets, rad/s, within the arm model's speed limits, held
  until the control tick that takes the next camera frame (``step="frame"``, the default) or
  for one control tick (``step="tick"``, ``episode.control_period``). They replace the
  controller's command in the approach, the servo and the descent; the phase machine keeps
  its transitions and time-outs, and the other phases (look, detect, track, grasp, lift,
  verify) run as in ``stackpick run`` between two steps.
* Reward 1 on a verified pick, else 0; the episode terminates when the pick is verified or
  fails. ``info``: ``phase``, ``time`` (s), and at the end ``success``, ``failure`` (a reason
  of :data:`~stackpick_sim.episodes.record.FAILURES`), ``failure_detail`` and the whole
  ``record``. ``info["reference_action"]`` is what our controller would command now, for
  the goal the next action is for: :class:`ReferencePolicy` acts on it. With
  ``step="tick"`` it reproduces ``stackpick run``'s episode exactly; with ``step="frame"``
  it holds each command for a camera frame (three ticks), so outcomes can differ.
* ``render_mode="rgb_array"``: the replay's side-by-side view (wrist camera with the
  detections | the overview camera), (480, 1280, 3) RGB.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from stackpick_sim.config.loader import load_scene
from stackpick_sim.episodes.episode import Episode, EpisodeHooks, EpisodeRun, TickInfo
from stackpick_sim.episodes.record import PHASES, EpisodeRecord
from stackpick_sim.episodes.video import VIEW_SIZE, wrist_view
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.pipeline import ControlGoal
from stackpick_sim.sim.camera import make_renderer
from stackpick_sim.sim.robot import VELOCITY_LIMITS

#: Largest seed ``reset()`` draws when no seed is given.
MAX_SEED = 2**31 - 1
#: Phases whose arm command the action gives (the others use the controller's).
ACTION_PHASES = ("approach", "servo", "descend")
#: Phases after which the agent is not asked again.
BLIND_PHASES = ("grasp", "lift", "verify")
FloatArray = NDArray[np.float64]
#: Actions are clipped to the speed limits widened by this share: a controller's command at
#: a limit can exceed it by floating-point rounding (1e-15 rad/s), which is not clipped.
LIMIT_ROUNDING = 1e-9


class StackPickEnv(gymnasium.Env[dict[str, Any], NDArray[np.float64]]):
    """See the module docstring."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}  # noqa: RUF012 (gymnasium's)

    def __init__(self, scene: str = "paper", overrides: tuple[str, ...] | list[str] = (),
                 render_mode: str | None = None, step: str = "frame") -> None:
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode {render_mode!r}; allowed: None, 'rgb_array'")
        if step not in ("frame", "tick"):
            raise ConfigError(f"step {step!r}; allowed: 'frame', 'tick'")
        self.cfg = load_scene(scene, tuple(overrides))
        self.render_mode = render_mode
        self.step_unit = step
        cam = self.cfg.camera
        self.limit = np.asarray(VELOCITY_LIMITS, dtype=np.float64)
        """(6,) joint speed limits of the arm model, rad/s (the action's bounds)."""
        self.action_space = spaces.Box(-self.limit, self.limit, shape=(6,), dtype=np.float64)
        self.observation_space = spaces.Dict({
            "image": spaces.Box(0, 255, (cam.height, cam.width, 3), dtype=np.uint8),
            "qpos": spaces.Box(-np.inf, np.inf, (6,), dtype=np.float64),
            "qvel": spaces.Box(-np.inf, np.inf, (6,), dtype=np.float64),
            "phase": spaces.Discrete(len(PHASES)),
        })
        self._run: EpisodeRun | None = None
        self._record: EpisodeRecord | None = None
        self._overview: Any = None
        self._events: Generator[ControlGoal, FloatArray | None, None] | None = None
        self._reference = np.zeros(6)
        self._reported = False
        """The step that ended the episode has been returned."""

    @property
    def episode(self) -> Episode:
        """The live episode (after :meth:`reset`)."""
        if self._run is None:
            raise gymnasium.error.ResetNeeded("call reset() first")
        return self._run.episode

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(0, MAX_SEED))
        self.close_episode()
        self._run = EpisodeRun(self.cfg, EpisodeHooks(keep_images=True,
                                                      on_tick=self._images_while_asked))
        self._run.reset(seed)
        self._record = None
        self._reported = False
        self._events = self._goals(self._run)
        self._advance(None, first=True)
        return self._observation(), self._info()

    @staticmethod
    def _images_while_asked(tick: TickInfo) -> None:
        """Render every frame for the observation until the grasp; after it the agent is not
        asked again (the frames the detector processes are rendered anyway)."""
        tick.episode.sensor.keep_images = tick.phase not in BLIND_PHASES

    @staticmethod
    def _goals(run: EpisodeRun) -> Generator[ControlGoal, FloatArray | None, None]:
        while (yield from run.ticks()):
            pass

    def _advance(self, action: FloatArray | None, first: bool = False) -> None:
        """Answer the pending goal with ``action`` and run on to the next goal the agent is
        asked for (or the episode's end)."""
        assert self._run is not None and self._events is not None
        ep = self._run.episode
        frames = ep.sensor.frames
        reply = action
        try:
            while True:
                goal = self._events.send(reply)
                if goal.phase not in ACTION_PHASES:
                    reply = None  # the grasp's hold: the controller's
                    continue
                if first or self.step_unit == "tick" or ep.sensor.frames > frames:
                    break
                reply = action
        except StopIteration:
            self._record = self._run.finish()
            self._reference = np.zeros(6)
            return
        try:
            self._reference = np.asarray(ep.controller.command(goal, ep.arm), dtype=float)
        except Exception:  # the controller has no answer here: the step will say so
            self._reference = np.zeros(6)

    def step(self, action: NDArray[np.float64]
             ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if self._run is None:
            raise gymnasium.error.ResetNeeded("call reset() first")
        if self._reported:
            raise gymnasium.error.ResetNeeded("the episode is over; call reset()")
        if self._record is None:  # else it ended before the agent was asked (e.g. no detection)
            bound = self.limit * (1.0 + LIMIT_ROUNDING)
            self._advance(np.clip(np.asarray(action, dtype=np.float64), -bound, bound))
        self._reported = self._record is not None
        terminated = self._record is not None
        reward = 1.0 if self._record is not None and self._record.success else 0.0
        return self._observation(), reward, terminated, False, self._info()

    def _observation(self) -> dict[str, Any]:
        ep = self.episode
        cell = ep.scene.cell
        last = ep.sensor.last
        cam = self.cfg.camera
        image = (last.image if last is not None and last.image is not None
                 else np.zeros((cam.height, cam.width, 3), np.uint8))
        return {"image": image,
                "qpos": cell.data.qpos[cell.arm_qpos_adr].astype(np.float64),
                "qvel": cell.data.qvel[cell.arm_dof_adr].astype(np.float64),
                "phase": PHASES.index(self._run.logic.phase) if self._run else 0}

    def _info(self) -> dict[str, Any]:
        assert self._run is not None
        ep = self._run.episode
        info: dict[str, Any] = {
            "phase": self._run.logic.phase, "time": float(ep.scene.cell.data.time),
            "reference_action": self._reference.copy()}
        if self._record is not None:
            rec = self._record
            info.update(success=rec.success, failure=rec.failure,
                        failure_detail=rec.failure_detail, record=rec.as_dict())
        return info

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode != "rgb_array":
            return None
        ep = self.episode
        cell = ep.scene.cell
        if self._overview is None:
            self._overview = make_renderer(cell.model, VIEW_SIZE[1], VIEW_SIZE[0])
        self._overview.update_scene(cell.data, camera="overview")
        right = self._overview.render()
        assert self._run is not None
        info = TickInfo(time=float(cell.data.time), phase=self._run.logic.phase,
                        observations=[], servo=None, episode=ep)
        last = ep.sensor.last
        left = (wrist_view(last, info)[:, :, ::-1] if last is not None and last.image is not None
                else np.zeros((VIEW_SIZE[1], VIEW_SIZE[0], 3), np.uint8))  # BGR -> RGB
        return np.ascontiguousarray(np.hstack([left, right]), dtype=np.uint8)

    def close_episode(self) -> None:
        """Release the running episode's renderers (reset and close do it)."""
        if self._events is not None:
            self._events.close()
            self._events = None
        if self._run is not None and self._record is None:
            self._run.finish()
        self._run = None
        if self._overview is not None:  # it renders one episode's model
            self._overview.close()
            self._overview = None

    def close(self) -> None:
        self.close_episode()


class ReferencePolicy:
    """Our controller as a policy: ``info["reference_action"]``, its command for the goal the
    next action is for."""

    def __call__(self, observation: dict[str, Any], info: dict[str, Any]) -> NDArray[np.float64]:
        return np.asarray(info.get("reference_action", np.zeros(6)), dtype=np.float64)
