"""The journal (durable, repaired, resumable), the lock, sweep grids and the gate's test."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from runs_fakes import fake_record

from stackpick_sim.exceptions import ConfigError
from stackpick_sim.runs import Journal, JournalError, LockError, RunLock, read_records
from stackpick_sim.runs.check import check, fisher_less
from stackpick_sim.runs.sweep import grid, parse_param, split_values


def _journal_with(tmp_path: Path, seeds: list[int]) -> Path:
    j = Journal(tmp_path, resume=False)
    for s in seeds:
        j.append(fake_record(s))
    j.close()
    return tmp_path / "results.jsonl"


def test_append_is_durable_line_by_line_and_compact_sorts(tmp_path: Path) -> None:
    path = _journal_with(tmp_path, [5, 2, 9])
    assert [json.loads(x)["seed"] for x in path.read_text().splitlines()] == [5, 2, 9]
    j = Journal(tmp_path, resume=True)
    j.compact()
    assert [json.loads(x)["seed"] for x in path.read_text().splitlines()] == [2, 5, 9]


@pytest.mark.parametrize("tail", [b'{"seed": 7, "sc', b'{"seed": 7}', b"\0\0\0\0",
                                  b'{"seed": 7, "x": 1}\0\0'])
def test_torn_last_line_is_repaired_on_resume(tmp_path: Path, tail: bytes) -> None:
    path = _journal_with(tmp_path, [1, 2])
    intact = path.read_bytes()
    with path.open("ab") as fh:
        fh.write(tail)
    with pytest.raises(JournalError, match="torn"):
        Journal(tmp_path, resume=False)
    j = Journal(tmp_path, resume=True)
    assert sorted(j.records) == [1, 2] and j.repair_note
    assert path.read_bytes() == intact  # truncated back to the last complete record
    j.append(fake_record(3))
    j.close()
    assert sorted(read_records(path)[0]) == [1, 2, 3]


def test_corrupt_line_in_the_middle_is_an_error_not_a_silent_drop(tmp_path: Path) -> None:
    path = _journal_with(tmp_path, [1])
    with path.open("a") as fh:
        fh.write("garbage\n" + json.dumps(fake_record(2).as_dict()) + "\n")
    with pytest.raises(JournalError, match="line 2 is not a record"):
        Journal(tmp_path, resume=True)


def test_existing_results_need_resume_and_seeds_are_never_duplicated(tmp_path: Path) -> None:
    _journal_with(tmp_path, [1])
    with pytest.raises(JournalError, match="--resume"):
        Journal(tmp_path, resume=False)
    j = Journal(tmp_path, resume=True)
    with pytest.raises(JournalError, match="already recorded"):
        j.append(fake_record(1))


def test_second_writer_is_refused_with_the_owner_named(tmp_path: Path) -> None:
    with RunLock(tmp_path):
        with pytest.raises(LockError, match=r"being written by another stackpick run \(pid"):
            RunLock(tmp_path)
        other = subprocess.run(
            [sys.executable, "-c", "import sys; from pathlib import Path; "
             "from stackpick_sim.runs.lock import RunLock; RunLock(Path(sys.argv[1]))",
             str(tmp_path)], capture_output=True, text=True)
        assert other.returncode != 0 and "LockError" in other.stderr
    RunLock(tmp_path).release()  # free again once released


def test_sweep_values_and_grid() -> None:
    assert split_values("[3,5],[5,7]") == ["[3,5]", "[5,7]"]
    assert split_values('"a,b",c') == ['"a,b"', "c"]
    p = parse_param("conveyor.speed=0.05,0.1")
    assert p.key == "conveyor.speed" and p.values == ("0.05", "0.1")
    cells = grid([p, parse_param("objects.count=[3,5],[5,7]")])
    assert len(cells) == 4
    assert cells[1].overrides == ("conveyor.speed=0.05", "objects.count=[5,7]")
    assert len({c.name for c in cells}) == 4
    with pytest.raises(ConfigError, match="KEY=V1,V2"):
        parse_param("conveyor.speed")


def test_fisher_matches_known_values() -> None:
    # Fisher's tea-tasting table (3/4 vs 1/4): one-sided p = 17/70 = 0.2429 (Fisher 1935).
    assert fisher_less(1, 4, 3, 4) == pytest.approx(17 / 70)
    assert fisher_less(5, 10, 5, 10) == pytest.approx(0.6719, abs=1e-4)
    assert fisher_less(0, 30, 24, 30) < 1e-9
    assert fisher_less(30, 30, 0, 30) == pytest.approx(1.0)


def _summary(k: int, n: int, centre: float = 1.0) -> dict:
    return {"successes": k, "episodes": n, "detection": {
        "center_error_px": {"median": centre}, "theta_x_error_deg": {"median": 1.0},
        "theta_y_error_deg": {"median": 1.0}}, "prediction_error_mm": {"median": 2.0},
        "cycle_time_s": {"median": 1.5}}


def test_gate_fails_on_a_significant_drop_and_on_error_regression() -> None:
    assert all(r.ok for r in check(_summary(30, 40), _summary(32, 40)))
    drop = check(_summary(15, 40), _summary(32, 40))
    assert not drop[0].ok and all(r.ok for r in drop[1:])
    worse = check(_summary(32, 40, centre=3.0), _summary(32, 40, centre=1.0))
    assert worse[0].ok and not worse[1].ok
