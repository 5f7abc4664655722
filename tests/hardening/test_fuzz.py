"""The fuzzer of tests/fuzz_targets.py on a short budget: for every reader of files and plugin output, a fixed set of
Hypothesis inputs (derandomized: the same on every run, so CI is never flaky) gives a correct result or one line,
never a traceback and never a file outside its folder. The long random budget is
``benchmarks/bench_reliability.py --fuzz MINUTES``."""

from __future__ import annotations

import pytest
from fuzz_targets import TARGETS
from hypothesis import HealthCheck, given, settings

#: inputs per target: a few seconds in all
EXAMPLES = {"run.json": 30, "trial records": 15, "KITTI .bin/.label": 15, "plugin births": 40}
SHORT = dict(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.mark.parametrize("name", list(TARGETS))
def test_every_input_gives_a_result_or_one_line(name):
    strategy, target = TARGETS[name]
    seen = {"ok": 0, "refused": 0}

    @settings(max_examples=EXAMPLES.get(name, 60), **SHORT)
    @given(strategy())
    def run(value):
        seen[target(value)] += 1

    run()
    assert seen["ok"] + seen["refused"] > 0
