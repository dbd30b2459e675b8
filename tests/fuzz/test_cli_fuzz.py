"""Property-based slice of the issue-16 fuzz campaign over the ``tpnet`` command line (CI: derandomized, small).

What is drawn and the oracle: bench/fuzz/fuzz_cli_cases.py's docstring (random argument lists for process, render,
inspect, dataset and bench over inputs that exist or not; each run exits 0, or 2 with a last stderr line
``tpnet CMD: error: ...``, never with a traceback). 12 examples, ~20 s on 2 cores; ``tpnet bench fuzz`` draws more.
"""

import pytest
from hypothesis import HealthCheck, Phase, given, settings

from tpnet_gpu.bench.fuzz.fuzz_cli_cases import check, cli_case, fixture

FUZZ = settings(derandomize=True, max_examples=12, deadline=None, database=None, phases=[Phase.generate],
                suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli_fuzz")
    return folder, fixture(folder)


@FUZZ
@given(argv=cli_case())
def test_fuzz_cli_exits_0_or_2_with_one_error_line_never_a_traceback(inputs, argv):
    folder, paths = inputs
    result = check(argv, paths, folder)
    assert result["failures"] == [], result
