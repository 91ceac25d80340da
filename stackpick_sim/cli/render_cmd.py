"""``stackpick render``: one scene at the look pose, its ground truth and pictures."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stackpick_sim.cli.common import add_scene_args, scene_from_args, seed_arg
from stackpick_sim.files import shown, write_text
from stackpick_sim.image_io import write_image
from stackpick_sim.sim.camera import make_renderer
from stackpick_sim.sim.snapshot import seeded_look_frame, truth_overlay

#: Size of the external overview picture, px.
OVERVIEW_SIZE = (480, 640)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``render`` subcommand."""
    p = sub.add_parser(
        "render", help="render one seeded scene from the look pose with its ground truth",
        description="Build and settle the scene of --seed, render the wrist camera at the look "
        "pose and write: frame.png (what the camera sees, with the scene's noise), truth.json "
        "(ground truth per object), overlay.png (ground-truth face ellipses, green = top "
        "objects), external.png (an outside view of the cell) and scene.xml (the compiled "
        "scene).")
    add_scene_args(p)
    p.add_argument("--seed", type=seed_arg, default=0, help="scene seed (default: 0)")
    p.add_argument("--out", type=Path, required=True, help="output directory (created)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the scene and write its files; prints a one-line summary per object."""
    cfg = scene_from_args(args)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)  # before the work: an unwritable --out fails fast
    scene, image, truth = seeded_look_frame(cfg, args.seed)
    write_image(out / "frame.png", image, order="rgb")
    write_image(out / "overlay.png", truth_overlay(image, truth), order="bgr")
    record = {"scene": cfg.name, "seed": args.seed, "attempts": scene.attempts, **truth.as_dict()}
    write_text(out / "truth.json", json.dumps(record, indent=1))
    write_text(out / "scene.xml", scene.cell.spec_xml)
    outside = make_renderer(scene.cell.model, *OVERVIEW_SIZE)
    try:
        outside.update_scene(scene.cell.data, camera="overview")
        write_image(out / "external.png", outside.render(), order="rgb")
    finally:
        outside.close()
    print(f"scene {cfg.name} seed {args.seed}: {len(truth.objects)} objects, "
          f"settled in {scene.attempts} attempt(s), {scene.build_wall_s:.2f} s; top: "
          f"{', '.join(truth.top_objects) or 'none'}")
    for o in truth.objects:
        e = o.ellipse
        shape = (f"ellipse ({e.cx:.1f}, {e.cy:.1f}) a={e.a:.1f} b={e.b:.1f} "
                 f"{e.angle_deg:.0f} deg" if e is not None else "face behind the camera")
        print(f"  {o.name:5s} {o.type_name:6s} tilt {o.tilt_deg:4.1f} deg  visible "
              f"{100 * o.visible_fraction:5.1f}%  {shape}{'  TOP' if o.is_top else ''}")
    print(f"wrote {shown(out)}/frame.png, overlay.png, external.png, truth.json, scene.xml")
    return 0
