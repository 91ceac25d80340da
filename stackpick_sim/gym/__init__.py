"""A Gymnasium environment of the pick: ``gymnasium.make("StackPick-v0", scene="paper")``.

Needs the optional extra ``stackpick-sim[gym]``. Importing this package registers the id
(``import stackpick_sim.gym``), or name the module in the id:
``gymnasium.make("stackpick_sim.gym:StackPick-v0")``. See
:class:`stackpick_sim.gym.env.StackPickEnv`.
"""

from __future__ import annotations

#: The environment's id.
ENV_ID = "StackPick-v0"

__all__ = ["ENV_ID", "register_envs"]


def register_envs() -> None:
    """Register StackPick-v0 with gymnasium (once)."""
    import gymnasium

    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="stackpick_sim.gym.env:StackPickEnv")


try:
    register_envs()
except ImportError:  # gymnasium not installed: nothing to register with
    pass
