"""Property-based slice of the issue-16 fuzz campaign over ``Pipeline`` (CI: derandomized, small).

What is drawn and the oracles: bench/fuzz/fuzz_pipeline_cases.py's docstring (frames of any rig, size, colour, dtype,
magnitude, with NaN/inf pixels and disparity ranges: nothing raises, outputs of the documented shapes, finite
confidence where measured and 0 elsewhere, a finite first-stage answer; bad constructor arguments: an error
naming the argument). 16 examples, ~20 s on 2 cores; ``tpnet bench fuzz`` draws many more.
"""

from hypothesis import HealthCheck, given, settings

from tpnet_gpu.bench.fuzz.fuzz_pipeline_cases import cases, check

FUZZ = settings(derandomize=True, max_examples=16, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FUZZ
@given(cases())
def test_fuzz_pipeline_outputs_as_documented_and_bad_arguments_named(case):
    assert check(case)["failures"] == []
