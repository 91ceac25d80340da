"""Mutated run-directory files, as hypothesis strategies, and what each must end in.

A family is a strategy of file contents (bytes) and a function that feeds one example to the
code that reads such a file and names the outcome: ``result`` (read and used), ``pass`` /
``fail`` (``stackpick check``'s verdicts) or ``refused`` (one StackpickError, or exit code 2
with one line on stderr). Anything else (another exception, several lines, a record kept that
breaks the schema) raises AssertionError. tests/test_runs_fuzz.py runs a few hundred examples;
benchmarks/fuzz_runs.py runs thousands and counts the outcomes.
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st
from runs_fakes import fake_record

from stackpick_sim.cli.main import main
from stackpick_sim.episodes.record import EpisodeRecord, PoseErrors
from stackpick_sim.episodes.schema import record_from_dict
from stackpick_sim.episodes.summary import summarize
from stackpick_sim.exceptions import StackpickError
from stackpick_sim.runs.journal import RESULTS_FILE, Journal, read_records
from stackpick_sim.runs.replay import load_state
from stackpick_sim.runs.spec import RunSpec
from stackpick_sim.runs.sweep import SWEEP_FILE, load_sweep

#: Any JSON value, small.
JSON: st.SearchStrategy[Any] = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=10), inner,
                                                                 max_size=4),
    max_leaves=12)


def _paths(value: Any, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key path of nested objects: ("a",), ("a", "b"), ..."""
    if not isinstance(value, dict):
        return []
    out = []
    for k, v in value.items():
        out.append((*prefix, k))
        out += _paths(v, (*prefix, k))
    return out


def _set(doc: dict[str, Any], path: tuple[str, ...], value: Any, *, delete: bool = False
         ) -> dict[str, Any]:
    out = json.loads(json.dumps(doc))
    node = out
    for k in path[:-1]:
        node = node[k]
    if delete:
        node.pop(path[-1], None)
    else:
        node[path[-1]] = value
    return out


def _dumps(value: Any) -> bytes:
    return json.dumps(value).encode()


def mutated_json(base: dict[str, Any]) -> st.SearchStrategy[bytes]:
    """``base`` itself, or with one change: a value replaced, a key removed or added, the
    whole document replaced, cut short, raw bytes, another encoding, or nesting deeper than
    any parser."""
    paths = _paths(base)
    text = _dumps(base)
    return st.one_of(
        st.just(text),
        st.tuples(st.sampled_from(paths), JSON).map(lambda pv: _dumps(_set(base, *pv))),
        st.sampled_from(paths).map(lambda p: _dumps(_set(base, p, None, delete=True))),
        st.tuples(st.text(max_size=10), JSON).map(lambda kv: _dumps({**base, kv[0]: kv[1]})),
        JSON.map(_dumps),
        st.integers(0, len(text)).map(lambda n: text[:n]),
        st.binary(max_size=300),
        st.sampled_from(["utf-16", "utf-32", "latin-1"]).map(
            lambda enc: json.dumps(base, ensure_ascii=False).encode(enc)),
        st.integers(1, 100_000).map(lambda n: b"[" * n + b"]" * n),
    )


# --- results.jsonl ----------------------------------------------------------------------------

def full_record(seed: int) -> EpisodeRecord:
    """A record with every kind of field set (poses, phases, wall breakdown)."""
    pose = PoseErrors(estimated=(100.0, 50.0, 1.0, -2.0), actual=(101.0, 49.5, 0.5, -1.0))
    return EpisodeRecord(seed=seed, scene="paper", detector="ours", tracker_frame="belt",
                         belt_speed=0.1, success=True, picked_object="obj1",
                         target_object="obj1", top_objects=["obj1"], lift_height_m=0.1,
                         detection=pose, pick_estimate=pose, prediction_error_px=1.5,
                         prediction_error_mm=0.7, cycle_time_s=1.5, phases={"look": 0.0},
                         frames=40, frames_processed=12, wall_breakdown_s={"render": 0.5})


BASE_LINES = [_dumps(r.as_dict()) for r in
              (fake_record(0), full_record(1), fake_record(2), fake_record(3))]


@st.composite
def mutated_results(draw: st.DrawFn) -> bytes:
    """results.jsonl with one line mutated (it may gain newlines) and maybe a torn tail."""
    lines = list(BASE_LINES)
    i = draw(st.integers(0, len(lines) - 1))
    lines[i] = draw(mutated_json(json.loads(lines[i])))
    data = b"".join(line + b"\n" for line in lines)
    cut = draw(st.integers(0, 40))
    return data[:len(data) - cut] if draw(st.booleans()) else data


def _check_records(records: dict[int, Any]) -> None:
    for seed, rec in records.items():
        assert rec.seed == seed
        assert record_from_dict(json.loads(json.dumps(rec.as_dict()))) == rec
    summarize(list(records.values()))  # whatever was kept, the summary can be made


def read_results(data: bytes, work: Path) -> str:
    """``read_records`` (check, report, replay): every record valid, or refused."""
    path = work / RESULTS_FILE
    path.write_bytes(data)
    try:
        records, _, _ = read_records(path)
    except StackpickError:
        return "refused"
    _check_records(records)
    return "result"


def resume_results(data: bytes, work: Path) -> str:
    """A journal opened for resume: drops invalid records, or refuses."""
    (work / RESULTS_FILE).write_bytes(data)
    try:
        journal = Journal(work, resume=True)
    except StackpickError:
        return "refused"
    journal.close()
    _check_records(journal.records)
    _check_records(read_records(work / RESULTS_FILE)[0])  # the rewritten file reads strictly
    return "dropped" if journal.dropped else "result"


# --- run.json, sweep.json, summaries, stored states -------------------------------------------

def read_run_json(data: bytes, work: Path) -> str:
    """RunSpec.from_dir (resume and replay)."""
    (work / "run.json").write_bytes(data)
    try:
        spec = RunSpec.from_dir(work)
    except StackpickError:
        return "refused"
    assert isinstance(spec.scene, str) and all(isinstance(o, str) for o in spec.overrides)
    return "result"


SWEEP_BASE = {"scene": "paper", "overrides": [], "params": {"conveyor.speed": ["0.1", "0.2"]},
              "seeds": [0, 1], "cells": {"conveyor.speed=0.1": ["conveyor.speed=0.1"],
                                         "conveyor.speed=0.2": ["conveyor.speed=0.2"]}}


def read_sweep_json(data: bytes, work: Path) -> str:
    """load_sweep (sweep --resume, report)."""
    (work / SWEEP_FILE).write_bytes(data)
    try:
        desc = load_sweep(work)
    except StackpickError:
        return "refused"
    for name in desc["cells"]:
        assert (work / "cells" / name).resolve().parent == (work / "cells").resolve()
    return "result"


SUMMARY_BASE = {"episodes": 40, "successes": 38,
                "detection": {"center_error_px": {"median": 0.5},
                              "theta_x_error_deg": {"median": 0.2},
                              "theta_y_error_deg": {"median": 0.2}},
                "prediction_error_mm": {"median": 0.8}, "cycle_time_s": {"median": 1.5}}


def check_baseline(data: bytes, work: Path) -> str:
    """``stackpick check`` against a mutated baseline: pass, fail, or exit 2 with one line."""
    current, baseline = work / "current.json", work / "baseline.json"
    current.write_text(json.dumps(SUMMARY_BASE))
    baseline.write_bytes(data)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        code = main(["check", str(current), "--baseline", str(baseline)])
    if code == 2:
        assert len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
        return "refused"
    assert code in (0, 1) and not err.getvalue(), (code, err.getvalue())
    return "pass" if code == 0 else "fail"


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


STATE_BASE = _npy(np.linspace(-1.0, 1.0, 7))


@st.composite
def mutated_npy(draw: st.DrawFn) -> bytes:
    """A stored state spliced, cut, of another dtype or shape, pickled, or random bytes."""
    kind = draw(st.sampled_from(["state", "splice", "cut", "array", "object", "bytes"]))
    if kind == "state":
        return _npy(np.array(draw(st.lists(st.floats(), min_size=1, max_size=12))))
    if kind == "splice":
        at = draw(st.integers(0, len(STATE_BASE) - 1))
        return STATE_BASE[:at] + draw(st.binary(min_size=1, max_size=16)) + STATE_BASE[at + 4:]
    if kind == "cut":
        return STATE_BASE[:draw(st.integers(0, len(STATE_BASE) - 1))]
    if kind == "array":
        dtype = draw(st.sampled_from(["float64", "float32", "int64", "uint8", "bool",
                                      "complex128", "U3"]))
        shape = draw(st.lists(st.integers(0, 5), max_size=3))
        values = draw(st.sampled_from([0.0, 1.5, np.nan, np.inf]))
        with np.errstate(invalid="ignore"):
            return _npy(np.full(shape, values if dtype != "U3" else "ab").astype(dtype))
    if kind == "object":
        return _npy(np.array([{"x": 1}, None], dtype=object))
    return draw(st.binary(max_size=300))


def read_state(data: bytes, work: Path) -> str:
    """The replay's reader of initial_qpos.npy / final_qpos.npy."""
    path = work / "initial_qpos.npy"
    path.write_bytes(data)
    try:
        state = load_state(path)
    except StackpickError:
        return "refused"
    assert state.dtype == np.float64 and state.ndim == 1 and np.isfinite(state).all()
    return "result"


@dataclass(frozen=True)
class Family:
    """Inputs of one kind and the reader they go to."""

    name: str
    strategy: st.SearchStrategy[bytes]
    run: Callable[[bytes, Path], str]


FAMILIES: tuple[Family, ...] = (
    Family("results.jsonl read", mutated_results(), read_results),
    Family("results.jsonl resume", mutated_results(), resume_results),
    Family("run.json", mutated_json({"scene": "paper", "overrides": ["conveyor.speed=0.2"]}),
           read_run_json),
    Family("sweep.json", mutated_json(SWEEP_BASE), read_sweep_json),
    Family("check --baseline", mutated_json(SUMMARY_BASE), check_baseline),
    Family("qpos.npy", mutated_npy(), read_state),
)


def run_in_tempdir(family: Family, data: bytes) -> str:
    """One example in a fresh directory."""
    with tempfile.TemporaryDirectory() as tmp:
        return family.run(data, Path(tmp))
