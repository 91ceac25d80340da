"""Fuzz the readers of run directories with thousands of mutated files; count the outcomes.

    python benchmarks/fuzz_runs.py [--examples 2000]

Families (tests/runs_fuzz_families.py, which tests/test_runs_fuzz.py runs a few hundred
times in CI): results.jsonl read strictly (check, report, replay) and opened for resume,
run.json, sweep.json, ``stackpick check --baseline`` and the replay's stored states. Each
input must end in ``result`` / ``dropped`` (resume dropped invalid records) / ``pass`` /
``fail`` (check's verdicts) or ``refused`` (one StackpickError, or exit code 2 with one
line); anything else is counted as ``crash`` with its first message. Results go to
benchmarks/results/fuzz_runs.md and .json, with the commit and the command.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from hypothesis import HealthCheck, given, settings

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from runs_fuzz_families import FAMILIES, Family, run_in_tempdir

RESULTS = Path(__file__).parent / "results"


def fuzz(family: Family, examples: int) -> tuple[Counter[str], list[str]]:
    """Outcome counts of ``examples`` inputs of ``family``, and the first crash messages."""
    counts: Counter[str] = Counter()
    crashes: list[str] = []

    @settings(max_examples=examples, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(data=family.strategy)
    def one(data: bytes) -> None:
        try:
            counts[run_in_tempdir(family, data)] += 1
        except Exception as exc:
            counts["crash"] += 1
            if len(crashes) < 5:
                crashes.append(f"{type(exc).__name__}: {str(exc)[:200]} <- {data[:80]!r}")

    one()
    return counts, crashes


def main() -> int:
    """Run every family, print and write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=2000, help="inputs per family")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, check=False).stdout.strip()
    rows = []
    for family in FAMILIES:
        t0 = time.perf_counter()
        counts, crashes = fuzz(family, args.examples)
        rows.append({"family": family.name, "inputs": sum(counts.values()),
                     "outcomes": dict(sorted(counts.items())), "crashes": crashes,
                     "wall_s": round(time.perf_counter() - t0, 1)})
        print(f"{family.name:22s} {rows[-1]['inputs']:6d} inputs  {rows[-1]['outcomes']}  "
              f"{rows[-1]['wall_s']} s", flush=True)
        for c in crashes:
            print(f"    crash: {c}")
    command = f"python benchmarks/fuzz_runs.py --examples {args.examples}"
    lines = [f"# Fuzzing the run-directory readers (commit {commit})", "",
             f"`{command}`", "", "| family | inputs | outcomes | crashes | wall s |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['family']} | {r['inputs']} | "
              + ", ".join(f"{k} {v}" for k, v in r["outcomes"].items())
              + f" | {r['outcomes'].get('crash', 0)} | {r['wall_s']} |" for r in rows]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "fuzz_runs.md").write_text("\n".join(lines) + "\n")
    (RESULTS / "fuzz_runs.json").write_text(json.dumps(
        {"commit": commit, "command": command, "families": rows}, indent=1))
    return 1 if any(r["outcomes"].get("crash") for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
