"""Figures of runs at scale: throughput with 1 and 2 local workers, and kill/resume trials.

    python benchmarks/bench_runs.py throughput [--seeds 100:116] [--scene paper]
    python benchmarks/bench_runs.py kill [--trials 20] [--seeds 0:6]

``throughput`` runs the same seeds with 1 and with 2 worker processes, in this one run of
the script, and reports episodes/s of each and their ratio (the machine's other load
affects both), plus the 1000-episode projection. ``kill`` starts ``stackpick run`` (oracle
detector, few seeds: fast), SIGKILLs its whole process group at a uniformly random moment
of a full run's duration, sometimes appends a torn half line (a power cut mid-write),
resumes, and checks that results.jsonl holds exactly one record per seed, each equal to the
reference run's except for wall times. Results go to benchmarks/results/runs_<name>.md/json.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from stackpick_sim.cli.common import parse_seeds
from stackpick_sim.episodes.record import WALL_CLOCK_KEYS, Record
from stackpick_sim.runs.journal import read_records
from stackpick_sim.runs.runner import RunJob, make_executor, run_dirs
from stackpick_sim.runs.spec import RunSpec

RESULTS = Path(__file__).parent / "results"
STACKPICK = [sys.executable, "-m", "stackpick_sim.cli.main"]
#: A torn last line, as a power cut in the middle of a write leaves it.
TORN_LINE = b'{"seed": 3, "scene": "pap'
#: 1000 episodes (a full evaluation batch) in at most this long, s.
TARGET_1000_S = 600.0


def _strip(rec: Record) -> dict[str, Any]:
    return {k: v for k, v in rec.as_dict().items() if k not in WALL_CLOCK_KEYS}


def throughput(args: argparse.Namespace) -> dict[str, Any]:
    """Episodes/s with 1 and 2 workers on the same seeds."""
    seeds = parse_seeds(args.seeds)
    spec = RunSpec(scene=args.scene, overrides=tuple(args.set))
    out: dict[str, Any] = {"scene": args.scene, "overrides": args.set, "seeds": args.seeds,
                           "cores": len(os.sched_getaffinity(0))}
    records: dict[int, list[dict[str, Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, 2):
            job = RunJob(key="b", spec=spec, seeds=seeds, out=Path(tmp) / f"w{workers}")
            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            load0 = os.getloadavg()[0]
            stats = run_dirs([job], make_executor("local", workers=workers),
                             show_progress=False)
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)  # workers are joined by now
            cpu = (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime)
            out[f"worker_cpu_s_per_episode_{workers}"] = cpu / len(seeds)
            out[f"load_avg_1min_before_after_{workers}"] = [load0, os.getloadavg()[0]]
            out[f"episodes_per_s_{workers}"] = stats.episodes_per_s
            out[f"wall_s_{workers}"] = stats.wall_s
            out[f"success_rate_{workers}"] = stats.summaries["b"]["success_rate"]
            got, _, _ = read_records(job.out / "results.jsonl")
            records[workers] = [_strip(got[s]) for s in sorted(got)]
    out["ratio_2_over_1"] = out["episodes_per_s_2"] / out["episodes_per_s_1"]
    out["records_identical"] = records[1] == records[2]
    out["projected_1000_s_2_workers"] = 1000 / out["episodes_per_s_2"]
    # What 2 idle cores would give: the workers' CPU time per episode, two at a time.
    out["projected_1000_s_2_idle_cores"] = 1000 * out["worker_cpu_s_per_episode_2"] / 2
    out["meets_1000_in_600_s"] = out["projected_1000_s_2_workers"] <= TARGET_1000_S
    return out


def _run(cmd: list[str], **kw: Any) -> subprocess.Popen[bytes]:
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, **kw)


def kill_trials(args: argparse.Namespace) -> dict[str, Any]:
    """SIGKILL at a random moment, (sometimes) tear the last line, resume, check."""
    rng = random.Random(args.rng_seed)
    seeds = parse_seeds(args.seeds)
    base = [*STACKPICK, "run", "--scene", "paper", "--detector", "oracle", "--seeds",
            args.seeds, "--workers", "2", "--quiet"]
    trials: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        ref_dir = Path(tmp) / "ref"
        t0 = time.perf_counter()
        subprocess.run([*base, "--out", str(ref_dir)], check=True, capture_output=True)
        full_s = time.perf_counter() - t0
        ref, _, _ = read_records(ref_dir / "results.jsonl")
        for i in range(args.trials):
            d = Path(tmp) / f"t{i}"
            delay = rng.uniform(0.0, full_s)
            proc = _run([*base, "--out", str(d)])
            time.sleep(delay)
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            results = d / "results.jsonl"
            before = len(read_records(results)[0]) if results.exists() else 0
            torn = i % 2 == 1 and results.exists()
            if torn:
                with results.open("ab") as fh:
                    fh.write(TORN_LINE)
            done = subprocess.run([*base, "--out", str(d), "--resume"], capture_output=True)
            got, _, _ = read_records(results)
            lines = results.read_text().splitlines()
            ok = (done.returncode == 0 and len(lines) == len(seeds)
                  and sorted(got) == seeds
                  and all(_strip(got[s]) == _strip(ref[s]) for s in seeds))
            trials.append({"trial": i, "kill_after_s": round(delay, 2),
                           "records_before_resume": before, "torn_line": torn,
                           "lines_after": len(lines), "ok": ok,
                           "stderr": done.stderr.decode()[-300:] if not ok else ""})
            print(trials[-1], flush=True)
    return {"seeds": args.seeds, "full_run_s": full_s, "trials": len(trials),
            "passed": sum(t["ok"] for t in trials),
            "lost_or_duplicated": sum(not t["ok"] for t in trials), "detail": trials}


def _markdown(name: str, res: dict[str, Any]) -> str:
    lines = [f"# bench_runs {name}", "", "| figure | value |", "|---|---|"]
    lines += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |"
              for k, v in res.items() if k != "detail"]
    if "detail" in res:
        lines += ["", "| trial | killed after s | records before resume | torn line | ok |",
                  "|---|---|---|---|---|"]
        lines += [f"| {t['trial']} | {t['kill_after_s']} | {t['records_before_resume']} | "
                  f"{t['torn_line']} | {t['ok']} |" for t in res["detail"]]
    return "\n".join(lines) + "\n"


def main() -> None:
    """Parse the arguments, measure, write the results."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="what", required=True)
    t = sub.add_parser("throughput")
    t.add_argument("--scene", default="paper")
    t.add_argument("--seeds", default="100:116")
    t.add_argument("--set", action="append", default=[])
    k = sub.add_parser("kill")
    k.add_argument("--trials", type=int, default=20)
    k.add_argument("--seeds", default="0:6")
    k.add_argument("--rng-seed", type=int, default=0)
    args = p.parse_args()
    res = throughput(args) if args.what == "throughput" else kill_trials(args)
    name = args.what if args.what == "kill" or not args.set else f"{args.what}_custom"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"runs_{name}.json").write_text(json.dumps(res, indent=1))
    (RESULTS / f"runs_{name}.md").write_text(_markdown(name, res))
    print(_markdown(name, res))


if __name__ == "__main__":
    main()
