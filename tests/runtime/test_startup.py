"""Start-up (docs/platform.md §4): what the light entry points import, the kernel caches a second `tpnet process`
hits, and Taichi's quick front end (tpnet_gpu/runtime/taichi_setup.py). Oracles: ``sys.modules`` of a fresh process; the
files of Taichi's offline cache and Warp's kernel cache (a run that compiled a kernel adds one); Taichi's own
behaviour for class kernels and its compile errors. No timings (those are bench_startup's)."""

import os
import subprocess
import sys
import textwrap

import pytest
import torch

from tpnet_gpu.runtime import taichi_setup
from tpnet_gpu.cli import main

HEAVY = ("torch", "warp", "taichi", "scipy")


def _imported(code: str) -> set[str]:
    """The heavy top-level packages a fresh process has imported after running ``code``."""
    probe = code + "\nimport sys\nprint(' '.join(sorted({m.partition('.')[0] for m in sys.modules})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return set(done.stdout.split()) & set(HEAVY)


def test_package_and_help_import_no_kernel_language_or_torch():
    code = "import tpnet_gpu, tpnet_gpu.cli\ntpnet_gpu.cli.build_parser().format_help()"
    assert _imported(code) == set()


def test_reading_inputs_imports_no_kernel_language_or_renderer():
    # The inputs of `tpnet process` (scene folders, raws, images) are read before the pipeline is built.
    assert _imported("import tpnet_gpu.io.stereo_io, tpnet_gpu.scenes.folder") == set()


def _cache_files(root) -> set[str]:
    """Compiled kernels under a cache root: Taichi's .tic files and Warp's module folders."""
    taichi = {p.name for p in (root / "taichi").glob("*.tic")}
    warp = {p.name for p in (root / "warp").glob("*/wp_*")}
    return taichi | warp


@pytest.mark.slow
def test_second_process_compiles_no_kernel(tmp_path):
    # A fresh cache: the first `tpnet process` (Taichi, the CPU default above 320x240) compiles every kernel it
    # runs; the second, a new process with the same cache, must find them all and add none (Taichi keys a
    # kernel by its IR: a kernel re-specialised per process or per call would add a file).
    # TI_ADVANCED_OPTIMIZATION=0 in both: Taichi's IR optimiser is most of a cold compile (fused_tiles 94 CPU-s
    # of 166 for the whole frame; 20 without it), and the cache key is the front end's IR (before those passes)
    # plus the compile config, the same in both processes, so a kernel re-specialised per process still adds a file.
    assert main(["render", str(tmp_path / "s"), "--width", "48", "--height", "32", "--supersample", "1"]) == 0
    cache = tmp_path / "cache"
    env = {**os.environ, "TPNET_CACHE_DIR": str(cache), "WARP_CACHE_PATH": str(cache / "warp"),
           "TI_ADVANCED_OPTIMIZATION": "0"}
    command = [sys.executable, "-m", "tpnet_gpu.cli", "process", str(tmp_path / "s"), "--out", str(tmp_path / "o"),
               "--device", "cpu", "--backend", "taichi", "--overwrite", "--no-figures"]  # the second replaces the first
    seen = []
    for _ in range(2):
        done = subprocess.run(command, capture_output=True, text=True, timeout=900, env=env)
        assert done.returncode == 0, done.stderr[-2000:]
        seen.append(_cache_files(cache))
    assert len([name for name in seen[0] if name.endswith(".tic")]) >= 5  # pad, centres, convert, correlate, texture
    assert seen[1] == seen[0]


def test_quick_front_end_is_installed():
    from taichi.lang import kernel_impl
    from taichi.lang.ast import ast_transformer_utils

    assert tuple(taichi_setup.ti.__version__[:2]) in taichi_setup.FRONT_END_VERSIONS  # else this test is moot
    assert kernel_impl._inside_class is taichi_setup._inside_class
    assert ast_transformer_utils.ASTTransformerContext.get_pos_info is taichi_setup._position


ti = taichi_setup.ti


@ti.data_oriented
class Scaler:
    """A class kernel: Taichi binds ``self`` only when its class-body test says the kernel is in a class."""

    def __init__(self, factor: float):
        self.factor = factor

    @ti.kernel
    def run(self, x: ti.types.ndarray()):
        for i in range(x.shape[0]):
            x[i] *= self.factor


@ti.kernel
def _misspelt(x: ti.types.ndarray()):
    for i in range(x.shape[0]):
        x[i] = no_such_name  # noqa: F821 - the compile error under test


def test_class_kernels_and_compile_errors_with_the_quick_front_end():
    taichi_setup.init_taichi("cpu")
    x = torch.ones(4)
    Scaler(3.0).run(x)
    assert x.tolist() == [3.0] * 4
    with pytest.raises(ti.TaichiNameError) as error:
        _misspelt(x)
    # where: this file, the line and its source (the position the quick front end keeps)
    line = next(i for i, text in enumerate(open(__file__), 1) if "x[i] = no_such_name" in text)
    assert f'{__file__}", line {line}, in _misspelt' in str(error.value)
    assert "x[i] = no_such_name" in str(error.value) and 'Name "no_such_name" is not defined' in str(error.value)


def test_debug_mode_keeps_taichi_positions(tmp_path):
    # TPNET_TAICHI_DEBUG=1: Taichi's own position text (with its caret hint) stays, for bounds-check messages.
    script = tmp_path / "debug_positions.py"
    script.write_text(textwrap.dedent("""
        from taichi.lang.ast import ast_transformer_utils
        from tpnet_gpu.runtime import taichi_setup
        print(ast_transformer_utils.ASTTransformerContext.get_pos_info is taichi_setup._position)
    """))
    env = {**os.environ, "TPNET_TAICHI_DEBUG": "1"}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-1] == "False"
