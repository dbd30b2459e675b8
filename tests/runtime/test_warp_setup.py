"""warp_setup: Warp's debug builds through TPNET_WARP_DEBUG (issue 16: the campaign's --debug set the mode too
late and ran release builds). Oracle: a kernel reading index 10 of a 4-element array - a debug build stops the
process with Warp's bounds assertion, a release build returns (whatever it read)."""

import os
import subprocess
import sys
import textwrap

import pytest

from tpnet_gpu.runtime import warp_setup

SCRIPT = textwrap.dedent("""
    import warp as wp
    from tpnet_gpu.runtime.warp_setup import init_warp
    init_warp()

    @wp.kernel
    def read(a: wp.array(dtype=wp.float32), out: wp.array(dtype=wp.float32), i: int):
        out[0] = a[i]

    a, out = wp.zeros(4, dtype=wp.float32, device="cpu"), wp.zeros(1, dtype=wp.float32, device="cpu")
    wp.launch(read, dim=1, inputs=[a, out, 10], device="cpu")
    wp.synchronize()
    print("mode", wp.config.mode, "returned")
""")


@pytest.mark.slow
@pytest.mark.parametrize("debug", [False, True], ids=["release", "debug"])
def test_warp_debug_env_builds_bounds_checked_kernels(tmp_path, debug):
    script = tmp_path / "oob.py"
    script.write_text(SCRIPT)
    env = {**os.environ, warp_setup.DEBUG_ENV: "1" if debug else "0"}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    if debug:
        assert done.returncode != 0 and "Assertion failed" in done.stderr + done.stdout, done.stderr[-1000:]
    else:
        assert done.returncode == 0 and "mode release returned" in done.stdout, done.stderr[-1000:]
