"""sim subpackage."""

from stackpick_sim.liboutput import route_mujoco_warnings

# Every process that simulates imports this package (also the spawned run workers): keep
# MuJoCo's warnings out of MUJOCO_LOG.TXT in the working directory.
route_mujoco_warnings()
