"""Property tests: mutated results.jsonl, run.json, sweep.json, baselines and stored states
each end in a result or one clear refusal (StackpickError, or exit code 2 and one line).

A few hundred examples in all, to keep CI fast; benchmarks/fuzz_runs.py runs thousands.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from runs_fuzz_families import FAMILIES, Family, run_in_tempdir

#: Examples per family in CI.
EXAMPLES = 60


@pytest.mark.parametrize("family", FAMILIES, ids=[f.name for f in FAMILIES])
def test_mutated_run_files_end_in_a_result_or_one_refusal(family: Family) -> None:
    seen: set[str] = set()

    @settings(max_examples=EXAMPLES, deadline=None, database=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(data=family.strategy)
    def one(data: bytes) -> None:
        seen.add(run_in_tempdir(family, data))  # raises on a crash or a kept bad record

    one()
    # The mutations reach both sides: some inputs are refused, others read.
    assert "refused" in seen and len(seen) >= 2, seen
