"""Fuzz the input boundaries and count the outcomes.

Families (each input is seeded, so a run repeats exactly):

* ``arrays``: arrays of random shape, dtype, memory layout and values (NaN, inf, extremes)
  into :func:`stackpick_sim.vision.detect`;
* ``image-files``: random bytes, and PNG/JPEG/TIFF/BMP/WebP/PNM files cut short or with
  bytes changed, given to ``stackpick detect FILE --json``;
* ``scene-files``: ``scenes/paper.toml`` with pieces inserted, deleted or replaced, loaded
  as a scene;
* ``set-values``: ``--set KEY=VALUE`` with known and unknown keys and random values.

Outcomes: ``ok`` (a result, exit 0), ``clean error`` (one StackpickError, or exit 2 with one
line on stderr), ``crash`` (any other exception, more output lines, a worker that died) and
``timeout`` (no answer within --timeout). Inputs run in a spawned worker process that is
restarted after a crash or time-out; the first few crashing inputs of each family are saved
under --out to reproduce them.

    python benchmarks/fuzz.py --count 2000            # about 10 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import pickle
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from functools import partial
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

FAMILIES = ("arrays", "image-files", "scene-files", "set-values")
DTYPES = ("uint8", "uint16", "int8", "int16", "int32", "uint32", "int64", "float16", "float32",
          "float64", "bool", "complex64")
SPECIAL = (np.nan, np.inf, -np.inf, 0.0, -0.0, 1e300, -1e300, 1e-300, 255.0, 65535.0, -1.0)
TOML_PIECES = ("[", "]", "=", '"', "'", "\n", "[[", "1e300", "-1", "nan", "inf", "true", "{",
               "}", ",", ".", "#", "\\", "\x00", "\xff", "[conveyor]\n", "extends = 'paper'\n",
               "x = 1\n", "[" * 300, "0" * 400, "\ufeff", "\r\n")
SAVED_PER_FAMILY = 5
#: Largest random array, elements (a 320 x 240 x 3 frame).
MAX_ELEMENTS = 320 * 240 * 3


# --- inputs ---------------------------------------------------------------------------------

def random_array(rng: np.random.Generator) -> np.ndarray:
    """An array of random small shape, dtype, layout and values."""
    dtype = np.dtype(DTYPES[rng.integers(len(DTYPES))])
    ndim = int(rng.integers(0, 5))
    big = rng.random() < 0.05  # now and then a camera-sized frame
    shape = tuple(int(s) for s in rng.integers(0, 320 if big else 64, size=ndim))
    if ndim == 3 and rng.random() < 0.7:
        shape = (*shape[:2], int(rng.choice([1, 3, 4])))
    while np.prod(shape) > MAX_ELEMENTS:  # 4-D shapes and the like: keep each input small
        shape = tuple(max(1, s // 2) for s in shape)
    raw = rng.normal(128, 100, size=shape)
    if dtype.kind == "f":
        raw[rng.random(shape) < 0.02] = rng.choice(SPECIAL)
    with np.errstate(all="ignore"):
        array = raw.astype(dtype) if dtype.kind != "b" else raw > 128
    layout = rng.integers(4)
    if layout == 1:
        array = np.asfortranarray(array)
    elif layout == 2 and ndim:
        array = np.repeat(array, 2, axis=0)[::2]
    elif layout == 3 and ndim:
        array = array[::-1]
    return array


def _seed_files() -> list[bytes]:
    import cv2

    rng = np.random.default_rng(0)
    out = []
    for ext, dtype in ((".png", np.uint8), (".png", np.uint16), (".jpg", np.uint8),
                       (".tiff", np.uint8), (".tiff", np.float32), (".bmp", np.uint8),
                       (".webp", np.uint8), (".ppm", np.uint8)):
        img = (rng.random((48, 64, 3)) * 200).astype(dtype)
        ok, buf = cv2.imencode(ext, img)
        if ok:
            out.append(buf.tobytes())
    return out


def random_file(rng: np.random.Generator, seeds: list[bytes]) -> bytes:
    """Random bytes, or a valid image file mutated and perhaps cut short."""
    if rng.random() < 0.25:
        return rng.bytes(int(rng.integers(0, 512)))
    data = bytearray(seeds[rng.integers(len(seeds))])
    for _ in range(int(rng.integers(0, 10))):
        at = int(rng.integers(0, min(len(data), 64 if rng.random() < 0.7 else len(data))))
        data[at] = int(rng.integers(0, 256))
    if rng.random() < 0.4:
        data = data[:int(rng.integers(0, len(data) + 1))]
    return bytes(data)


def _piece(rng: np.random.Generator) -> str:
    if rng.random() < 0.6:
        return str(TOML_PIECES[rng.integers(len(TOML_PIECES))])
    return "".join(chr(int(c)) for c in rng.integers(1, 0x2FF, size=int(rng.integers(0, 8))))


def random_scene_text(rng: np.random.Generator, paper: str) -> bytes:
    """paper.toml with 1-4 pieces inserted, deleted or replaced; sometimes re-encoded."""
    text = paper
    for _ in range(int(rng.integers(1, 5))):
        at = int(rng.integers(0, len(text) + 1))
        text = text[:at] + _piece(rng) + text[at + int(rng.integers(0, 13)):]
    encoding = ("utf-8", "utf-16", "latin-1")[int(rng.choice(3, p=[0.9, 0.05, 0.05]))]
    return text.encode(encoding, "replace")


def random_override(rng: np.random.Generator, keys: list[str]) -> str:
    """KEY=VALUE with a known key (mostly) and a random value."""
    key = keys[rng.integers(len(keys))].replace("*", "large") if rng.random() < 0.9 \
        else _piece(rng)
    kind = rng.integers(5)
    if kind == 0:
        value = repr(float(rng.choice(SPECIAL)) * float(rng.choice([1, -1])))
    elif kind == 1:
        value = str(int(rng.integers(-(2**62), 2**62)))
    elif kind == 2:
        value = repr(float(rng.normal(0, 10)))
    elif kind == 3:
        value = str([round(float(x), 3) for x in rng.normal(0, 1, size=int(rng.integers(0, 5)))])
    else:
        value = _piece(rng) + _piece(rng)
    return f"{key}={value}"


def make_inputs(family: str, count: int, seed: int) -> Iterator[Any]:
    """The family's ``count`` seeded inputs, one at a time."""
    rng = np.random.default_rng([seed, FAMILIES.index(family)])
    make: Callable[[], Any]
    if family == "arrays":
        make = partial(random_array, rng)
    elif family == "image-files":
        make = partial(random_file, rng, _seed_files())
    elif family == "scene-files":
        from stackpick_sim.paths import SCENES_DIR

        make = partial(random_scene_text, rng, (SCENES_DIR / "paper.toml").read_text())
    else:
        from stackpick_sim.config.loader import known_keys

        make = partial(random_override, rng, known_keys())
    return (make() for _ in range(count))


# --- the worker -----------------------------------------------------------------------------

def _no_constant(name: str) -> None:
    raise ValueError(f"{name} in JSON output")


def _run_cli(argv: list[str]) -> str:
    """Run ``stackpick ARGV`` in this process with fds 1 and 2 captured; the outcome."""
    from stackpick_sim.cli.main import main

    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        try:
            code = main(argv)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        err.seek(0)
        lines = err.read().decode("utf-8", "replace").splitlines()
        out.seek(0)
        printed = out.read()
    if code == 0 and not lines:
        json.loads(printed, parse_constant=_no_constant)  # strict JSON: no NaN, Infinity
        return "ok"
    if code == 2 and len(lines) == 1 and "error:" in lines[0]:
        return "clean error"
    return f"crash: exit {code}, stderr {lines[:3]}"


def run_one(family: str, item: Any, tmp: str) -> str:
    """The outcome of one input; raises for a crash."""
    from stackpick_sim.exceptions import StackpickError

    try:
        if family == "arrays":
            from stackpick_sim.vision.detector import detect

            detect(item)
        elif family == "image-files":
            path = os.path.join(tmp, "in.png")
            Path(path).write_bytes(item)
            return _run_cli(["detect", path, "--json"])
        elif family == "scene-files":
            from stackpick_sim.config.loader import load_scene

            path = os.path.join(tmp, "in.toml")
            Path(path).write_bytes(item)
            load_scene(path)
        else:
            from stackpick_sim.config.loader import load_scene

            load_scene("paper", [item])
    except StackpickError:
        return "clean error"
    return "ok"


def worker(conn: Connection) -> None:
    """Answer (family, input) requests with outcomes until the pipe closes."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    with tempfile.TemporaryDirectory() as tmp:
        while True:
            try:
                family, item = conn.recv()
            except EOFError:
                return
            try:
                outcome = run_one(family, item, tmp)
            except Exception as exc:  # the crash class this counts
                outcome = f"crash: {type(exc).__name__}: {exc}"[:300]
            conn.send(outcome)


class Runner:
    """A spawned worker, restarted after a crash or a time-out."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.ctx = multiprocessing.get_context("spawn")
        self.proc: Any = None
        self.conn: Connection | None = None

    def _start(self) -> None:
        parent, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=worker, args=(child,), daemon=True)
        self.proc.start()
        self.conn = parent

    def _kill(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.join()
        self.proc = self.conn = None

    def run(self, family: str, item: Any) -> str:
        if self.conn is None:
            self._start()
        assert self.conn is not None
        self.conn.send((family, item))
        try:
            if not self.conn.poll(self.timeout):
                self._kill()
                return "timeout"
            return str(self.conn.recv())
        except (EOFError, ConnectionError):
            code = self.proc.exitcode if self.proc is not None else None
            self._kill()
            return f"crash: worker died (exit code {code})"

    def close(self) -> None:
        self._kill()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=2000, help="inputs per family")
    parser.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=30.0,
                        help="seconds one input may take (the first also imports everything)")
    parser.add_argument("--out", type=Path, default=Path("out/fuzz"),
                        help="where crashing inputs are saved")
    args = parser.parse_args()
    runner = Runner(args.timeout)
    print(f"{'family':12s} {'inputs':>7s} {'ok':>6s} {'clean error':>12s} {'crash':>6s} "
          f"{'timeout':>8s} {'s':>6s}")
    try:
        for family in args.families:
            inputs = make_inputs(family, args.count, args.seed)
            counts: Counter[str] = Counter()
            start = time.perf_counter()
            for index, item in enumerate(inputs):
                outcome = runner.run(family, item)
                kind = outcome.split(":")[0]
                counts[kind] += 1
                if kind in ("crash", "timeout") and counts[kind] <= SAVED_PER_FAMILY:
                    args.out.mkdir(parents=True, exist_ok=True)
                    with open(args.out / f"{family}-{index}.pickle", "wb") as fh:
                        pickle.dump({"family": family, "input": item, "outcome": outcome}, fh)
                    print(f"  {family} #{index}: {outcome}", file=sys.stderr)
            print(f"{family:12s} {args.count:7d} {counts['ok']:6d} {counts['clean error']:12d} "
                  f"{counts['crash']:6d} {counts['timeout']:8d} "
                  f"{time.perf_counter() - start:6.0f}", flush=True)
    finally:
        runner.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
