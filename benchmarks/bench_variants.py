"""Our detector on variants of the paper scene: does it hold beyond the scene it was built on?

Each variant is the paper scene with a few keys changed (VARIANTS: object colours, camera
height and resolution, light, pile shape). For each, ``stackpick bench-detect --methods
ours`` renders the seeds' frames in-process and scores them; the per-variant results go to
``--out``/NAME/, and one table of top success, F and pose errors to ``--out``/summary.md.
The paper scene's acceptance targets apply to the paper scene only; here they are a
yardstick.

    python benchmarks/bench_variants.py [--seeds 21000:21150] [--variants grey,high]
        [--out benchmarks/results/variants]

With ``--episodes``, whole picks instead: ``stackpick run`` (our detector, the scene's
tracker) on each variant, and one table of pick success, failures and prediction error at
the pick to ``--out``/summary.md (default ``--out`` then: benchmarks/results/variants_episodes;
the per-episode audit files stay out of git, see .gitignore).

Time: about 2-3 min per 150 frames and variant on this project's machine (building and
rendering the piles is most of it; flat piles take longest to build); with ``--episodes``
about 1.5 min per 150 episodes with two workers on an otherwise idle machine (flat piles:
~3.5 min). Variants whose piles are hard to build print generation warnings for the seeds
they skip.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stackpick_sim.cli.main import main

RESULTS = Path(__file__).resolve().parent / "results" / "variants"
EPISODE_RESULTS = RESULTS.with_name("variants_episodes")

#: name -> (what changes, the ``--set`` overrides of the paper scene).
VARIANTS: dict[str, tuple[str, list[str]]] = {
    "paper": ("the paper scene itself", []),
    "grey": ("both kinds light grey (the belt's hue)",
             ["object_types.large.rgba=[0.7,0.7,0.7,1.0]",
              "object_types.small.rgba=[0.7,0.7,0.7,1.0]"]),
    "redgreen": ("kinds red and green",
                 ["object_types.large.rgba=[0.8,0.2,0.2,1.0]",
                  "object_types.small.rgba=[0.2,0.7,0.3,1.0]"]),
    "onekind": ("large cylinders only", ['objects.types=["large"]']),
    "high": ("camera 0.40 m above the belt (faces ~25 % smaller)", ["camera.look_height=0.40"]),
    "hires": ("640x480 camera", ["camera.width=640", "camera.height=480"]),
    "dim": ("light 0.55, noise 4, light jitter 0.06",
            ["lights.intensity=0.55", "camera.noise_std=4", "lights.jitter=0.06"]),
    "flat": ("4-7 cylinders tilted at most 15 deg",
             ["objects.max_tilt_deg=15", "objects.count=[4,7]"]),
}


def _row(name: str, what: str, summary: dict) -> str:
    def err(key: str) -> str:
        s = summary[key]
        return f"{s['median']:.2f} / {s['p95']:.2f}"

    return (f"| {name} | {what} | {summary['frames_with_top']} | "
            f"{100 * summary['top_success']:.1f} % | {summary['f_measure']:.3f} | "
            f"{err('centre_err_px')} | {err('theta_x_err_deg')} | {err('theta_y_err_deg')} | "
            f"{summary['time_ms']['median']:.2f} |")


def _episode_row(name: str, what: str, summary: dict) -> str:
    lo, hi = summary["success_ci95"]
    failures = ", ".join(f"{k} {v}" for k, v in summary["failures"].items() if v) or "none"
    pred = summary["prediction_error_px"]
    return (f"| {name} | {what} | {summary['successes']}/{summary['episodes']} = "
            f"{100 * summary['success_rate']:.1f} % ({100 * lo:.1f}-{100 * hi:.1f}) | "
            f"{failures} | {pred['median']:.2f} / {pred['p95']:.2f} |")


def run() -> int:
    """Benchmark each variant asked for and write the summary; the first non-zero exit code
    of a variant's run, else 0."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", default="21000:21150",
                   help="seeds rendered for every variant (default 21000:21150)")
    p.add_argument("--variants", default=",".join(VARIANTS),
                   help=f"comma-separated subset of {','.join(VARIANTS)} (default: all)")
    p.add_argument("--episodes", action="store_true",
                   help="run pick episodes (stackpick run) instead of the detection benchmark")
    p.add_argument("--out", type=Path, default=None,
                   help=f"output directory (default {RESULTS}, with --episodes "
                        f"{EPISODE_RESULTS})")
    args = p.parse_args()
    if args.out is None:
        args.out = EPISODE_RESULTS if args.episodes else RESULTS
    names = [n.strip() for n in args.variants.split(",") if n.strip()]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown or not names:
        p.error(f"unknown variant(s) {unknown}; choose from {', '.join(VARIANTS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    rows, code = [], 0
    for name in names:
        what, sets = VARIANTS[name]
        out = args.out / name
        print(f"[{name}] {what}", flush=True)
        overrides = [a for s in sets for a in ("--set", s)]
        if args.episodes:
            got = main(["run", "--scene", "paper", *overrides, "--seeds", args.seeds,
                        "--detector", "ours", "--out", str(out), "--quiet"])
            if got == 0:
                summary = json.loads((out / "summary.json").read_text())
                rows.append(_episode_row(name, what, summary))
        else:
            got = main(["bench-detect", "--scene", "paper", *overrides, "--seeds", args.seeds,
                        "--methods", "ours", "--out", str(out), "--quiet"])
            if got == 0:
                summary = json.loads((out / "results.json").read_text())["methods"]["ours"]
                rows.append(_row(name, what, summary))
        code = code or got
    if args.episodes:
        head = [f"## Pick episodes on scene variants, seeds {args.seeds}", "",
                "Our detector, as `stackpick run`; success with its 95 % Wilson interval; "
                "prediction error at the pick, px, median / p95.", "",
                "| variant | change from the paper scene | success | failures | "
                "prediction error px |", "|---|---|---|---|---|"]
    else:
        head = [f"## Our detector on scene variants, seeds {args.seeds}", "",
                "Top success, P/R/F and errors as in `stackpick bench-detect`; errors median "
                "/ p95.", "",
                "| variant | change from the paper scene | frames | top success | F | "
                "centre px | theta_x deg | theta_y deg | time ms (med) |",
                "|---|---|---|---|---|---|---|---|---|"]
    table = "\n".join([*head, *rows, ""])
    (args.out / "summary.md").write_text(table)
    print(table)
    return code


if __name__ == "__main__":
    raise SystemExit(run())
