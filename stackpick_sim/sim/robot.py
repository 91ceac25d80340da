"""The robot: Denso VS-060 arm (models/vs060) with the suction tool (models/suction_cup).

:func:`robot_spec` composes the two MJCF files into one uncompiled :class:`mujoco.MjSpec`, the
arm's base at the world origin and the tool attached at the arm's ``flange`` site without a
name prefix, so every name below is valid in the composed model (and in any cell built on it).

Suction contact, a design note: the cup's contact surface is a ring of eight small spheres
(the lip of a bellows cup), not one flat cylinder. A flat-on-flat cylinder contact gives a
single contact point unless the global ``multiccd`` flag is on, and the tool cannot set that
flag for the cell that includes it (``<option>`` is not carried over by attachment); eight
sphere contacts spread over the lip are stable without it, so we leave ``multiccd`` off.
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ModelError
from stackpick_sim.paths import model_path

#: Arm joints, base to flange.
ARM_JOINTS: tuple[str, ...] = tuple(f"j{i}_joint" for i in range(1, 7))
#: Arm position actuators, named after their joints (same order as ARM_JOINTS).
ARM_ACTUATORS: tuple[str, ...] = tuple(f"j{i}" for i in range(1, 7))
#: Site at the J6 frame (the mounting flange): (-0.010, 0, 1.020) m in the world at q = 0.
FLANGE_SITE = "flange"
#: Suction cup tip (centre of the lip plane), tool +z = approach axis.
TOOL_SITE = "attachment_site"
#: The wrist camera (MuJoCo convention: looks along its -z, image up = its +y).
CAMERA = "wrist_cam"
#: Site with exactly the camera's pose, for IK targeting.
CAMERA_SITE = "camera_site"
#: Body holding the camera (its frame is the camera frame; lights added to it shine along -z).
CAMERA_BODY = "camera_link"
#: Suction cup body, the one the adhesion actuator pulls on.
CUP_BODY = "cup_link"
#: Adhesion actuator of the cup, ctrl in [0, 1] (0 off, 1 full vacuum).
SUCTION_ACTUATOR = "suction"
#: Name of the home keyframe (= the default look pose).
HOME_KEY = "home"

#: Joint speed limits, rad/s, in ARM_JOINTS order: Denso's vs060.urdf (denso_robot_ros).
VELOCITY_LIMITS: NDArray[np.float64] = np.array([3.927, 2.618, 2.858, 3.927, 3.022, 6.283])
VELOCITY_LIMITS.flags.writeable = False

ARM_MODEL = "vs060"
TOOL_MODEL = "suction_cup"
TOOL_ROOT_BODY = "bracket_link"

# MuJoCo warns on an empty-prefix attach, and again at every compile and save of that spec,
# that the spec "may not be saved correctly": a name clash risk. Our names are unique across
# the two files (a clash fails the compile), and robot_spec() saves the composed spec to MJCF
# and parses it back, which both proves it saves correctly and hands the caller a clean spec
# that no longer carries the warning.
_EMPTY_PREFIX_WARNING = "Attaching a spec with an empty prefix"


def _load_spec(path: Path) -> mujoco.MjSpec:
    """Parse and compile-check one MJCF file; ModelError naming the file if either fails."""
    if not path.is_file():
        raise ModelError(f"model file {path} does not exist")
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        spec.compile()
    except ValueError as exc:
        raise ModelError(f"model file {path} failed to compile: {exc}") from None
    return spec


def _attach_quietly(parent: mujoco.MjSpec, child: mujoco.MjSpec, site: mujoco.MjsSite) -> None:
    """Attach ``child`` at ``site`` with no name prefix, silencing only the empty-prefix warning.

    At attach time MuJoCo reports it through ``mju_warning``, whose default handler also
    appends to MUJOCO_LOG.TXT in the working directory; a temporary handler keeps it out of
    there. Any other warning raised during the attach is passed on as a Python warning.
    """
    previous = mujoco.get_mju_user_warning()
    caught: list[str] = []
    mujoco.set_mju_user_warning(caught.append)
    try:
        parent.attach(child, prefix="", site=site)
    finally:
        mujoco.set_mju_user_warning(previous)
    for message in caught:
        if not message.startswith(_EMPTY_PREFIX_WARNING):
            warnings.warn(f"MuJoCo: {message}", RuntimeWarning, stacklevel=3)


def robot_spec() -> mujoco.MjSpec:
    """The arm with the suction tool at its flange, as a fresh uncompiled spec (yours to edit).

    See :func:`robot_xml` for the composition; the composed MJCF is cached per file version.
    """
    return mujoco.MjSpec.from_string(robot_xml())


def robot_xml() -> str:
    """MJCF text of the arm with the suction tool at its flange (cached per file version)."""
    arm_path, tool_path = model_path(ARM_MODEL), model_path(TOOL_MODEL)
    return _composed_xml(arm_path, tool_path, _mtime(arm_path), _mtime(tool_path))


def _mtime(path: Path) -> int:
    return path.stat().st_mtime_ns if path.is_file() else -1


@functools.lru_cache(maxsize=4)
def _composed_xml(arm_path: Path, tool_path: Path, arm_mtime: int, tool_mtime: int) -> str:
    """The composition; the modification times only key the cache.

    The arm's base is at the world origin; the tool's frame coincides with the flange frame.
    The ``home`` keyframe gets ctrl = (arm qpos, suction 0). The spec is parsed back from the
    composed MJCF (see ``_EMPTY_PREFIX_WARNING``), which MuJoCo writes with 6 significant
    digits: joint ranges such as 2.094395 rad come back as 2.0944 (5e-6 rad off); nothing else
    changes measurably. Raises ModelError naming the file if a model file is missing or does
    not compile, or if the composition fails.
    """
    arm = _load_spec(arm_path)
    tool = _load_spec(tool_path)
    flange = arm.site(FLANGE_SITE)
    if flange is None:
        raise ModelError(f"model file {arm_path} has no site {FLANGE_SITE!r}")
    if tool.body(TOOL_ROOT_BODY) is None:
        raise ModelError(f"model file {tool_path} has no body {TOOL_ROOT_BODY!r}")
    _attach_quietly(arm, tool, flange)
    for key in arm.keys:
        if len(key.ctrl) == len(ARM_ACTUATORS):
            key.ctrl = [*key.ctrl, 0.0]
    what = f"{tool_path} attached to {arm_path} at site {FLANGE_SITE!r}"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_EMPTY_PREFIX_WARNING)
        try:
            arm.compile()
            xml = arm.to_xml()
        except ValueError as exc:
            raise ModelError(f"{what} failed to compile: {exc}") from None
    try:
        mujoco.MjSpec.from_string(xml)
    except ValueError as exc:
        raise ModelError(f"{what} compiled but its saved MJCF does not parse: {exc}") from None
    return xml
