"""The robot cell: arm + tool (robot.py) + conveyor + ring light + cylinders, built with MjSpec.

``build_cell(cfg, type_names)`` composes and compiles the model for one pile of cylinders of
the given kinds, resolves every name once, and solves the look pose. The belt is a static
box whose top surface moves along world +y (``surfacevel``); cylinders are free bodies
``obj0 .. objN-1`` with one geom each, parked on the floor outside the cell until placed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np
from numpy.typing import NDArray

from stackpick_sim.config.scene_config import ObjectTypeCfg, SceneConfig
from stackpick_sim.exceptions import ModelError
from stackpick_sim.geometry import MJ_CAM_TO_CV, CameraIntrinsics
from stackpick_sim.sim import appearance, robot
from stackpick_sim.sim.ik import look_pose_q
from stackpick_sim.sim.lens import render_padding

#: Belt box thickness, m (visual only: the top surface is what matters).
BELT_THICKNESS = 0.04
#: Belt speed the model is compiled with, m/s: any non-zero value (see _add_belt).
COMPILED_BELT_SPEED = 1.0
#: An object whose centre is this far below the belt surface has fallen off, m.
OFF_BELT_DROP = 0.01
#: Parked objects wait on the floor this far from the cell, m (outside every camera view).
PARK_X = -2.0
#: Spacing of parked objects along y, m.
PARK_SPACING = 0.2
#: Friction of the cylinders' surfaces: sliding (plastic on rubber), torsional and rolling
#: (m; MuJoCo's are lengths): a ~1 cm contact patch and a rolling resistance of ~3% of the
#: radius, so that a dropped cylinder stops spinning or rolling within a fraction of a second
#: as real ones on a rubber belt do (placeholders, not identified on a real cell).
OBJECT_FRICTION = (0.8, 0.01, 0.001)
#: Impedance ratio of frictional to normal contact forces (see compose_spec).
FRICTION_IMPRATIO = 10.0
#: Slices of a rendered cylinder: 64 keeps the polygonal rim within 0.12% of the true circle
#: (28, MuJoCo's default, is off by 0.6% of the radius, ~0.2 px at our scale).
CYLINDER_SLICES = 64
#: Summed diffuse intensity of the ring lights at ``lights.intensity = 1`` (each light gets its
#: share times its ring factor), chosen so that a face square to the camera at the look
#: distance stays well below saturation: two overlapping faces of one colour must differ.
RING_TOTAL_DIFFUSE = 0.5
#: The ring lights are small lamps behind a diffuser: half their light falls off with the
#: square of the distance (normalised at this distance, m: the look height), half does not.
#: A face nearer the camera is brighter (~8% per 3 cm), which is how a real ring light
#: separates stacked faces of one colour, without the top of a tall stack saturating.
RING_LIGHT_NOMINAL_DISTANCE = 0.30
#: Spot cutoff of the ring lights, degrees: wide enough to light the whole view.
RING_LIGHT_CUTOFF_DEG = 60.0
#: Seed-sequence stream of the belt's wear marks (``[seed, BELT_TEXTURE_STREAM]``).
BELT_TEXTURE_STREAM = 6
#: Seed-sequence stream of the clutter beside the belt (``[seed, CLUTTER_STREAM]``).
CLUTTER_STREAM = 8
#: Clutter lies this far beyond the belt's edge, m (from, to): just past the side rails. The
#: look-pose view (0.25 m across the belt) sees it on belts narrower than about 0.2 m; the
#: camera sees it on wider ones when the arm moves off the belt's centre line.
CLUTTER_BAND = (0.025, 0.08)
#: ... and this far along the belt from the look point, m.
CLUTTER_SPAN = 0.15
#: The external camera ``overview``: where it stands and what it looks at, world frame, m.
OVERVIEW_EYE = (1.25, -0.95, 0.85)
OVERVIEW_TARGET = (0.35, 0.0, 0.2)
OVERVIEW_FOVY_DEG = 45.0


@dataclass(frozen=True, kw_only=True)
class ObjectInfo:
    """One cylinder in a compiled cell, with its MuJoCo ids resolved once."""

    name: str
    type_name: str
    radius: float
    """m"""
    height: float
    """m"""
    body_id: int
    geom_id: int
    qpos_adr: int
    """Start of its 7 free-joint qpos entries (x, y, z, qw, qx, qy, qz)."""
    dof_adr: int
    """Start of its 6 free-joint dofs."""
    visual_geom_ids: tuple[int, ...] = ()
    """Every geom drawn for it (its collision cylinder unless hidden, decals, a tube)."""


def camera_intrinsics(cfg: SceneConfig) -> CameraIntrinsics:
    """The wrist camera's intrinsics and lens distortion."""
    cam = cfg.camera
    return CameraIntrinsics.from_fovy(cam.fovy_deg, cam.width, cam.height, cam.distortion)


def look_point(cfg: SceneConfig) -> NDArray[np.float64]:
    """(3,) world point on the belt's centre line straight below the camera at the look pose, m."""
    return np.array([cfg.conveyor.x, 0.0, cfg.conveyor.top_z])


@dataclass(kw_only=True)
class Cell:
    """A compiled cell: model, data and every id the hot loops need."""

    cfg: SceneConfig
    model: mujoco.MjModel
    data: mujoco.MjData
    spec_xml: str
    """The compiled scene as MJCF text, for audit and replay."""
    objects: tuple[ObjectInfo, ...]
    camera_id: int
    belt_geom_id: int
    arm_qpos_adr: NDArray[np.int_]
    arm_dof_adr: NDArray[np.int_]
    arm_actuator_ids: NDArray[np.int_]
    suction_actuator_id: int
    ring_light_ids: NDArray[np.int_]
    look_q: NDArray[np.float64]
    """Arm joint angles of the look pose, rad."""
    intrinsics: CameraIntrinsics
    belt_skin_mocap: int | None = None
    """Mocap index of the belt's textured skin (``conveyor.texture``), which moves with the
    belt surface; None: a plain belt."""

    @property
    def look_point(self) -> NDArray[np.float64]:
        """World point on the belt surface straight below the camera at the look pose, m."""
        return look_point(self.cfg)

    def set_belt_speed(self, speed: float) -> None:
        """Set the belt surface speed along world +y, m/s."""
        self.model.geom_surfacevel[self.belt_geom_id, 1] = speed

    def fell_off_belt(self, obj: ObjectInfo) -> bool:
        """Whether ``obj`` left the belt sideways or fell below its surface (not its ends)."""
        belt = self.cfg.conveyor
        pos = self.data.xpos[obj.body_id]
        return bool(abs(pos[0] - belt.x) > belt.width / 2 or pos[2] < belt.top_z - OFF_BELT_DROP)

    def set_arm(self, q: NDArray[np.float64]) -> None:
        """Put the arm at joint angles ``q`` (rad) at rest, with its position targets there."""
        self.data.qpos[self.arm_qpos_adr] = q
        self.data.qvel[self.arm_dof_adr] = 0.0
        self.data.ctrl[self.arm_actuator_ids] = q

    def world_T_cam(self) -> NDArray[np.float64]:
        """(4, 4) pose of the wrist camera in the world, OpenCV camera axes (needs mj_forward)."""
        out = np.eye(4)
        out[:3, :3] = self.data.cam_xmat[self.camera_id].reshape(3, 3) @ MJ_CAM_TO_CV
        out[:3, 3] = self.data.cam_xpos[self.camera_id]
        return out


def _add_belt(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    belt = cfg.conveyor
    spec.add_material(name="belt_mat", rgba=[0.16, 0.16, 0.17, 1.0], specular=0.05,
                      shininess=0.1)
    spec.add_material(name="frame_mat", rgba=[0.55, 0.57, 0.6, 1.0], specular=0.3)
    centre = [belt.x, 0.0, belt.top_z - BELT_THICKNESS / 2]
    spec.worldbody.add_geom(
        name="belt", type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[belt.width / 2, belt.length / 2, BELT_THICKNESS / 2], pos=centre,
        material="belt_mat", friction=[belt.friction, 0.005, 0.0001],
        # MuJoCo only moves surfaces whose surfacevel is non-zero when the model is compiled:
        # a belt compiled at rest ignores later run-time speeds. build_cell stops it after
        # compiling; Conveyor sets the running speed.
        surfacevel=[0.0, COMPILED_BELT_SPEED, 0.0, 0.0, 0.0, 0.0])
    # Side rails and legs: visual only, so they never touch the objects.
    for side in (-1.0, 1.0):
        spec.worldbody.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.01, belt.length / 2, 0.03],
            pos=[belt.x + side * (belt.width / 2 + 0.01), 0.0, belt.top_z - 0.03],
            material="frame_mat", contype=0, conaffinity=0, group=2)
        for end in (-1.0, 1.0):
            leg_h = belt.top_z - BELT_THICKNESS
            spec.worldbody.add_geom(
                type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.015, 0.015, leg_h / 2],
                pos=[belt.x + side * belt.width / 2, end * (belt.length / 2 - 0.05), leg_h / 2],
                material="frame_mat", contype=0, conaffinity=0, group=2)


def _add_lights(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    lights = cfg.lights
    spec.visual.headlight.ambient = [lights.ambient] * 3
    spec.visual.headlight.diffuse = [0.0, 0.0, 0.0]
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]
    # A dim room light so the external view is readable; the ring light dominates the wrist view.
    spec.worldbody.add_light(name="room_light", pos=[0.4, 0.0, 2.5], dir=[0, 0, -1],
                             diffuse=[0.35, 0.35, 0.35], specular=[0.0, 0.0, 0.0],
                             castshadow=False, cutoff=80.0)
    cam = spec.camera(robot.CAMERA)
    body = spec.body(robot.CAMERA_BODY)
    if cam is None or body is None:
        raise ModelError(f"robot model lacks camera {robot.CAMERA!r} in body {robot.CAMERA_BODY!r}")
    # Ring offsets lie in the camera's image plane (camera x, y), the lights shine along -z.
    flat_rot = np.zeros(9)
    mujoco.mju_quat2Mat(flat_rot, np.asarray(cam.quat, dtype=float))
    cam_rot = flat_rot.reshape(3, 3)
    n = len(lights.ring)
    for i, factor in enumerate(lights.ring):
        ang = 2.0 * math.pi * i / n
        offset = cam_rot @ np.array([math.cos(ang), math.sin(ang), 0.0]) * lights.ring_radius
        diffuse = RING_TOTAL_DIFFUSE / n * lights.intensity * factor
        body.add_light(name=f"ring_light_{i}", pos=list(np.asarray(cam.pos) + offset),
                       dir=list(cam_rot @ np.array([0.0, 0.0, -1.0])),
                       diffuse=[diffuse] * 3, specular=[0.3 * diffuse] * 3,
                       castshadow=cfg.camera.shadows and (lights.shadow_lamps == 0
                                                          or i < lights.shadow_lamps),
                       cutoff=RING_LIGHT_CUTOFF_DEG,
                       exponent=2.0,
                       attenuation=[0.5, 0.0, 0.5 / RING_LIGHT_NOMINAL_DISTANCE**2])


def _add_overview_camera(spec: mujoco.MjSpec) -> None:
    eye, target = np.array(OVERVIEW_EYE), np.array(OVERVIEW_TARGET)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    cam = spec.worldbody.add_camera(name="overview", pos=list(eye), fovy=OVERVIEW_FOVY_DEG)
    # MuJoCo cameras look along their -z, with the image's right and up as their x and y.
    rot = np.column_stack([right, up, -forward])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.flatten())
    cam.quat = quat


def _add_kind_assets(spec: mujoco.MjSpec, tname: str, t: ObjectTypeCfg) -> None:
    spec.add_material(name=f"{tname}_mat", rgba=list(t.rgba), specular=t.specular,
                      shininess=t.shininess)
    if t.kind in ("printed", "can"):
        art = (appearance.printed_texture(t, appearance.kind_rng(tname, t))
               if t.kind == "printed" else appearance.can_texture(t))
        appearance.add_texture(spec, f"{tname}_art", art)
        spec.add_material(name=f"{tname}_decal", textures=["", f"{tname}_art"],
                          specular=t.specular, shininess=t.shininess)
        appearance.add_mesh(spec, f"{tname}_decal",
                            appearance.annulus(0.0, t.radius, appearance.DECAL_LIFT))
    elif t.kind == "tape":
        appearance.add_mesh(spec, f"{tname}_tube",
                            appearance.tube(t.hole_radius, t.radius, t.height))


def _add_kind_visuals(body: mujoco.MjsBody, i: int, tname: str, t: ObjectTypeCfg,
                      geom: mujoco.MjsGeom) -> None:
    """Decals on both caps (a printed lid, a can), or a tube drawn instead of the cylinder."""
    if t.kind == "cylinder":
        return
    # Visual geoms add no mass: the body keeps the solid cylinder's inertia.
    body.explicitinertial = True
    body.mass = t.mass
    body.ipos = [0.0, 0.0, 0.0]
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    # A solid cylinder's inertia, or a thick-walled tube's (a tape roll round its hole).
    r2 = t.radius**2 + (t.hole_radius**2 if t.kind == "tape" else 0.0)
    body.inertia = [t.mass * (3 * r2 + t.height**2) / 12] * 2 + [t.mass * r2 / 2]
    visual = {"contype": 0, "conaffinity": 0, "group": 0, "type": mujoco.mjtGeom.mjGEOM_MESH}
    if t.kind == "tape":
        geom.group = 3  # collision only: the tube with its hole is what the cameras see
        body.add_geom(name=f"obj{i}_tube", meshname=f"{tname}_tube", material=f"{tname}_mat",
                      **visual)
        return
    for side, quat in (("top", [1.0, 0.0, 0.0, 0.0]), ("bottom", [0.0, 1.0, 0.0, 0.0])):
        body.add_geom(name=f"obj{i}_{side}", meshname=f"{tname}_decal",
                      material=f"{tname}_decal", pos=[0.0, 0.0, 0.0], quat=quat,
                      **visual).pos = [0.0, 0.0, (t.height / 2) * (1 if side == "top" else -1)]


def _add_objects(spec: mujoco.MjSpec, cfg: SceneConfig, type_names: Sequence[str]) -> None:
    for tname in sorted(set(type_names)):
        _add_kind_assets(spec, tname, cfg.object_types[tname])
    for i, tname in enumerate(type_names):
        t = cfg.object_types[tname]
        body = spec.worldbody.add_body(name=f"obj{i}",
                                       pos=[PARK_X, PARK_SPACING * i, t.height / 2])
        body.add_freejoint(name=f"obj{i}_joint")
        geom = body.add_geom(name=f"obj{i}_geom", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                             size=[t.radius, t.height / 2, 0.0], mass=t.mass,
                             material=f"{tname}_mat", friction=list(OBJECT_FRICTION), condim=4)
        _add_kind_visuals(body, i, tname, t, geom)


def _add_belt_skin(spec: mujoco.MjSpec, cfg: SceneConfig, seed: int) -> None:
    """The belt's worn rubber: a textured plate on a mocap body that the conveyor moves."""
    belt = cfg.conveyor
    rgb = appearance.belt_texture(np.random.default_rng([seed, BELT_TEXTURE_STREAM]), belt.width)
    appearance.add_texture(spec, "belt_wear", rgb)
    spec.add_material(name="belt_skin_mat", textures=["", "belt_wear"], specular=0.05,
                      shininess=0.1)
    w, half = belt.width / 2, belt.length / 2
    repeats = belt.length / appearance.BELT_TEXTURE_PERIOD
    verts = np.array([[-w, -half, 0.0], [w, -half, 0.0], [w, half, 0.0], [-w, half, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, repeats], [0.0, repeats]])
    appearance.add_mesh(spec, "belt_skin", (verts, faces, uv))
    body = spec.worldbody.add_body(name="belt_skin", mocap=True,
                                   pos=[belt.x, 0.0, belt.top_z + appearance.DECAL_LIFT])
    body.add_geom(name="belt_skin", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="belt_skin",
                  material="belt_skin_mat", contype=0, conaffinity=0, group=0)


def _add_clutter(spec: mujoco.MjSpec, cfg: SceneConfig, rng: np.random.Generator) -> None:
    """``conveyor.clutter`` loose items beside the belt: boxes and tins, visual only."""
    belt = cfg.conveyor
    for i in range(belt.clutter):
        side = 1.0 if rng.random() < 0.5 else -1.0
        x = belt.x + side * (belt.width / 2 + rng.uniform(*CLUTTER_BAND))
        y = rng.uniform(-CLUTTER_SPAN, CLUTTER_SPAN)
        size = rng.uniform(0.01, 0.025, 3)
        rgba = [*rng.uniform(0.15, 0.9, 3), 1.0]
        yaw = rng.uniform(0, math.pi)
        box = rng.random() < 0.6
        geom_type = mujoco.mjtGeom.mjGEOM_BOX if box else mujoco.mjtGeom.mjGEOM_CYLINDER
        half_h = size[2] if box else size[1]
        spec.worldbody.add_geom(
            name=f"clutter{i}", type=geom_type, size=list(size),
            pos=[x, y, belt.top_z + half_h], quat=[math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)],
            rgba=rgba, contype=0, conaffinity=0, group=0)


def compose_spec(cfg: SceneConfig, type_names: Sequence[str], seed: int = 0) -> mujoco.MjSpec:
    """The uncompiled cell for a pile of cylinders of kinds ``type_names``; ``seed`` draws
    the belt's wear marks (``conveyor.texture``)."""
    spec = robot.robot_spec()
    spec.modelname = f"stackpick_{cfg.name}"
    spec.option.timestep = cfg.sim.timestep
    # An elliptic friction cone with a high impedance ratio makes static friction stiff: with
    # MuJoCo's default pyramidal cone a cylinder leaning on a neighbour's rim creeps down it
    # at a few degrees per second, which real piles do not do.
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = FRICTION_IMPRATIO
    spec.visual.quality.numslices = CYLINDER_SLICES
    spec.visual.quality.shadowsize = cfg.lights.shadow_map_px
    # The wrist camera renders a wider pinhole image when its lens distorts (sim/lens.py).
    pad = 2 * render_padding(camera_intrinsics(cfg))
    spec.visual.global_.offwidth = max(cfg.camera.width + pad, 640)
    spec.visual.global_.offheight = max(cfg.camera.height + pad, 480)
    cam = spec.camera(robot.CAMERA)
    if cam is not None:
        cam.fovy = cfg.camera.fovy_deg
    spec.add_texture(name="floor_tex", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=256, height=256,
                     rgb1=[0.42, 0.43, 0.45], rgb2=[0.38, 0.39, 0.41])
    spec.add_material(name="floor_mat", textures=["", "floor_tex"], texrepeat=[8, 8])
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                            size=[4.0, 4.0, 0.05], material="floor_mat")
    _add_belt(spec, cfg)
    _add_lights(spec, cfg)
    _add_overview_camera(spec)
    _add_objects(spec, cfg, type_names)
    if cfg.conveyor.texture:
        _add_belt_skin(spec, cfg, seed)
    if cfg.conveyor.clutter:
        _add_clutter(spec, cfg, np.random.default_rng([seed, CLUTTER_STREAM]))
    return spec


def _audit_xml(spec: mujoco.MjSpec) -> str:
    """The compiled spec as MJCF. MJCF cannot hold a generated texture's pixels: each is
    written as a flat texture of its mean colour (the XML is for audit; episodes rebuild
    their cells, textures included, from the scene and seed)."""
    for tex in spec.textures:
        if len(tex.data):
            rgb = np.frombuffer(bytes(tex.data), dtype=np.uint8).reshape(-1, tex.nchannel)
            tex.data = b""
            tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_FLAT
            tex.rgb1 = list(rgb[:, :3].mean(axis=0) / 255.0)
    return str(spec.to_xml())


@lru_cache(maxsize=16)
def _look_q_cached(xml: str, look: tuple[float, float, float], height: float) -> tuple[float, ...]:
    model = mujoco.MjModel.from_xml_string(xml)
    return tuple(look_pose_q(model, np.array(look), height))


def build_cell(cfg: SceneConfig, type_names: Sequence[str], seed: int = 0) -> Cell:
    """Compose, compile and index the cell; the arm is put at the look pose, the belt stopped."""
    spec = compose_spec(cfg, type_names, seed)
    try:
        model = spec.compile()
    except ValueError as exc:
        raise ModelError(f"the composed cell failed to compile: {exc}") from None
    xml = _audit_xml(spec)
    data = mujoco.MjData(model)
    objects = []
    for i, tname in enumerate(type_names):
        t = cfg.object_types[tname]
        body_id = model.body(f"obj{i}").id
        jnt = model.body_jntadr[body_id]
        shown = tuple(g for g in range(model.ngeom) if model.geom_bodyid[g] == body_id
                      and model.geom_group[g] < 3)
        objects.append(ObjectInfo(
            name=f"obj{i}", type_name=tname, radius=t.radius, height=t.height, body_id=body_id,
            geom_id=model.geom(f"obj{i}_geom").id, qpos_adr=int(model.jnt_qposadr[jnt]),
            dof_adr=int(model.jnt_dofadr[jnt]), visual_geom_ids=shown))
    arm_joints = [model.joint(name) for name in robot.ARM_JOINTS]
    look = tuple(float(v) for v in look_point(cfg))
    # The look pose depends only on the robot and the look geometry, not on the objects.
    look_q = np.array(_look_q_cached(robot.robot_xml(), look, cfg.camera.look_height))
    cell = Cell(
        cfg=cfg, model=model, data=data, spec_xml=xml, objects=tuple(objects),
        camera_id=model.camera(robot.CAMERA).id, belt_geom_id=model.geom("belt").id,
        arm_qpos_adr=np.array([j.qposadr[0] for j in arm_joints]),
        arm_dof_adr=np.array([j.dofadr[0] for j in arm_joints]),
        arm_actuator_ids=np.array([model.actuator(a).id for a in robot.ARM_ACTUATORS]),
        suction_actuator_id=model.actuator(robot.SUCTION_ACTUATOR).id,
        ring_light_ids=np.array([model.light(f"ring_light_{i}").id
                                 for i in range(len(cfg.lights.ring))]),
        look_q=look_q,
        belt_skin_mocap=(int(model.body_mocapid[model.body("belt_skin").id])
                         if cfg.conveyor.texture else None),
        intrinsics=camera_intrinsics(cfg),
    )
    cell.set_belt_speed(0.0)
    cell.set_arm(look_q)
    mujoco.mj_forward(model, data)
    return cell
