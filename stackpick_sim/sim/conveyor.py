"""The running belt: nominal speed plus the paper's noise n(k), and objects leaving its end.

The belt is a static geom whose surface moves (``surfacevel``); friction carries the objects.
Every ``conveyor.jitter_period`` seconds the speed is redrawn as
``speed + N(0, speed_jitter)`` (never negative). An object that passes the belt's far end
is removed: parked on the floor outside the cell, at rest, and reported as gone.
"""

from __future__ import annotations

import mujoco
import numpy as np

from stackpick_sim.sim.appearance import BELT_TEXTURE_PERIOD
from stackpick_sim.sim.cell import PARK_SPACING, PARK_X, Cell


class Conveyor:
    """Drives the belt of a cell; call :meth:`update` once per physics step."""

    def __init__(self, cell: Cell, rng: np.random.Generator) -> None:
        self._cell = cell
        self._rng = rng
        self._next_redraw = 0.0
        self.speed = 0.0
        """Current belt speed, m/s along world +y."""
        self.removed: list[str] = []
        """Names of the objects that left the belt's end, in order."""

    def start(self) -> None:
        """Start the belt; objects resting on it (or on each other) start moving with it.

        A pile on a running belt moves with the belt; giving it the belt's velocity at once
        avoids an artificial jerk that a standing pile would get from a belt starting at full
        speed.
        """
        self._next_redraw = self._cell.data.time
        self.update()
        for obj in self._cell.objects:
            self._cell.data.qvel[obj.dof_adr + 1] = self.speed

    def stop(self) -> None:
        """Stop the belt."""
        self.speed = 0.0
        self._cell.set_belt_speed(0.0)

    def update(self) -> None:
        """Redraw the speed noise when due and remove objects past the belt's end."""
        cfg = self._cell.cfg.conveyor
        now = self._cell.data.time
        if now >= self._next_redraw:
            noise = cfg.speed_jitter * self._rng.standard_normal() if cfg.speed_jitter else 0.0
            self.speed = max(0.0, cfg.speed + noise)
            self._cell.set_belt_speed(self.speed)
            self._next_redraw = now + cfg.jitter_period
        self._move_skin()
        self._remove_departed()

    def _move_skin(self) -> None:
        """Carry the belt's textured skin along with the surface for one physics step (it
        wraps back by whole texture periods, which look the same)."""
        skin = self._cell.belt_skin_mocap
        if skin is None:
            return
        pos = self._cell.data.mocap_pos[skin]
        pos[1] = (pos[1] + self.speed * self._cell.model.opt.timestep) % BELT_TEXTURE_PERIOD

    def _remove_departed(self) -> None:
        cell = self._cell
        end = cell.cfg.conveyor.length / 2
        newly = False
        for i, obj in enumerate(cell.objects):
            if obj.name in self.removed or cell.data.xpos[obj.body_id][1] <= end:
                continue
            adr = obj.qpos_adr
            cell.data.qpos[adr:adr + 7] = [PARK_X, PARK_SPACING * i, obj.height / 2, 1, 0, 0, 0]
            cell.data.qvel[obj.dof_adr:obj.dof_adr + 6] = 0.0
            self.removed.append(obj.name)
            newly = True
        if newly:
            mujoco.mj_forward(cell.model, cell.data)
