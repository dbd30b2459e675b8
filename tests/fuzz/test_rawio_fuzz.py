"""Property-based slice of the issue-16 fuzz campaign over the raw readers (CI: derandomized, small).

What is drawn and the oracle: bench/fuzz/fuzz_raw_cases.py's docstring (small DNGs and TIFFs, Bayer or not, with
bytes flipped, headers damaged, truncated, junk appended or emptied; each read gives a Bayer ``RawFrame``, a
``RawFormatError`` naming the file, or for a bad CFA name a ``ValueError`` naming ``cfa`` - never another
exception, a crash or a hang). The reads run in a child process (LibRaw is native code). 4 batches of 25 files,
~10 s on 2 cores; ``tpnet bench fuzz`` reads many more.
"""

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from tpnet_gpu.bench.fuzz.fuzz_raw_cases import raw_case, run

FUZZ = settings(derandomize=True, max_examples=4, deadline=None, database=None, phases=[Phase.generate],  # no
                # shrinking: each try is a child process; the failing case is printed whole
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FUZZ
@given(st.lists(raw_case(), min_size=25, max_size=25))
def test_fuzz_raw_readers_give_a_mosaic_or_a_clean_error_naming_the_file(batch):
    failures = [(case, f) for case, f in zip(batch, run(batch)) if f is not None]
    assert failures == []
