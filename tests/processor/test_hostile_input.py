"""Issue 16 regressions of TileProcessor (each named after the failure the fuzz campaign found).
Oracles: the argument rules of the processor's docstrings (refusals), a single-threaded run of the same frames
(threads), the float64 golden reference (huge pixel values; tolerance: the kernel tests' 1e-4 of the peak)."""

import os
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest
import torch

from tests.kernels.oracle import reference_clt, reference_corr
from tpnet_gpu import tables
from tpnet_gpu.processor import TileProcessor

H, W = 32, 48


@pytest.fixture
def frames():
    return np.random.default_rng(16).uniform(0, 4000, size=(4, H, W)).astype(np.float32)


@pytest.mark.parametrize("grid", [(0, 2), (1, 0)], ids=["no-rows", "no-cols"])
def test_issue16_zero_sized_kernel_grid_is_refused_not_a_crash(tmp_path, backend, grid):
    # In a subprocess: before the fix process() read an empty kernel buffer and died of SIGSEGV (Taichi's debug
    # mode hung). Now the constructor refuses the grid with a message naming the argument and the form.
    script = tmp_path / "kernels.py"
    script.write_text(textwrap.dedent(f"""
        import numpy as np
        from tpnet_gpu.processor import TileProcessor
        try:
            tp = TileProcessor(32, 48, kernels=np.ones((4, {grid[0]}, {grid[1]}, 3, 4, 8, 8), np.float32),
                               device="cpu", backend="{backend}")
            tp.process(np.ones((4, 32, 48), np.float32), 0.0)
        except ValueError as exc:
            print("refused:", exc)
    """))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TPNET_TAICHI_DEBUG": "1"})
    assert done.returncode == 0, done.stderr[-2000:]
    assert "refused: kernels: expected shape (cams=4, [rows >= 1, cols >= 1,] colours=3, 4, 8, 8), got (4, " \
           f"{grid[0]}, {grid[1]}, 3, 4, 8, 8)" in done.stdout


def test_issue16_complex_kernels_are_refused():
    with pytest.raises(TypeError, match="kernels: expected real values .* got complex64"):
        TileProcessor(H, W, kernels=np.ones((4, 3, 4, 8, 8), np.complex64), device="cpu")


def test_issue16_transposed_active_mask_is_refused(frames, backend):
    # A (tiles_x, tiles_y) mask has the right size but selects the wrong tiles; the flat (tiles,) form is the
    # row-major grid (oracle: the (tiles_y, tiles_x) mask's result).
    tp = TileProcessor(H, W, device="cpu", backend=backend)
    grid = np.zeros((H // 8, W // 8), dtype=bool)
    grid[1, 2:5] = True
    with pytest.raises(ValueError, match=r"active: expected a bool mask of shape \(4, 6\) .* got torch.bool of "
                                         r"shape \(6, 4\)"):
        tp.process(frames, 0.0, active=np.ascontiguousarray(grid.T))
    want = tp.process(frames, 0.0, active=grid).corr.clone()
    torch.testing.assert_close(tp.process(frames, 0.0, active=grid.reshape(-1)).corr, want, rtol=0, atol=0)


def test_issue16_shared_processor_never_swaps_results_between_threads(frames, backend):
    # Before: two threads sharing one processor got each other's results in 19-44 % of calls. Now the thread
    # that first gives it work owns it; another living thread is refused with a RuntimeError, and once the
    # owner has ended another thread may take it over. Oracle: each frame's single-threaded result.
    other = frames[:, ::-1].copy()
    tp = TileProcessor(H, W, device="cpu", backend=backend)
    want = {name: tp.process(f, 1.0).corr.clone() for name, f in (("a", frames), ("b", other))}
    got, errors, started, release = {}, [], threading.Event(), threading.Event()

    def owner():
        got["a"] = own.process(frames, 1.0).corr.clone()
        started.set()
        release.wait(60)
        got["a again"] = own.process(frames, 1.0).corr.clone()

    def intruder():
        try:
            own.process(other, 1.0)
        except RuntimeError as exc:
            errors.append(str(exc))

    own = TileProcessor(H, W, device="cpu", backend=backend)
    first = threading.Thread(target=owner, name="owner")
    first.start()
    started.wait(60)
    second = threading.Thread(target=intruder, name="intruder")
    second.start()
    second.join(60)
    release.set()
    first.join(60)
    assert len(errors) == 1 and "belongs to thread 'owner'" in errors[0] and "'intruder'" in errors[0], errors
    torch.testing.assert_close(got["a"], want["a"], rtol=0, atol=0)
    torch.testing.assert_close(got["a again"], want["a"], rtol=0, atol=0)
    # The owner has ended: a later thread takes the processor over and gets its own results.
    later = threading.Thread(target=lambda: got.__setitem__("b", own.process(other, 1.0).corr.clone()))
    later.start()
    later.join(60)
    torch.testing.assert_close(got["b"], want["b"], rtol=0, atol=0)


@pytest.mark.parametrize("cfa", [None, "GRBG"], ids=["mono", "bayer"])
def test_issue16_huge_pixel_values_give_the_reference_or_an_invalid_tile(frames, backend, cfa):
    # Before: pixels >= ~1e11 gave all-zero correlations (the squares in the fat-zero norm overflowed float32),
    # >= ~1e19 NaN, on tiles marked valid. Oracle: the float64 reference within the kernel tests' 1e-4 of the
    # peak up to layout.PIXEL_LIMIT (2^50); beyond it a pixel counts as not finite: its tiles are invalid and
    # their correlations zero.
    tp = TileProcessor(H, W, cfa=cfa, device="cpu", backend=backend)
    for gain in (1e11, 2.0**38):
        f = frames * np.float32(gain)
        out = tp.process(f, 1.5)
        valid = out.valid.numpy()
        want = reference_corr(reference_clt(f, out.centres.numpy(), cfa), tables.QUAD_PAIRS)[valid]
        assert valid.sum() == 8  # the interior tiles (4 x 6 grid, windows of the outer ring leave the image)
        assert np.abs(out.corr.numpy()[valid] - want).max() <= 1e-4 * np.abs(want).max()
    for gain in (1e19, 2.0**51):
        out = tp.process(frames * np.float32(gain), 1.5)
        assert not out.valid.numpy().any() and np.all(out.corr.numpy() == 0)


def test_issue16_kernel_modules_are_hashed_with_every_kernel_source():
    # Warp 1.19 leaves the functions given to tile_map out of a module's content hash, so a warm cache served
    # stale code after such an edit. Oracle: a digest of kernels/*.py made here, in every module's options.
    import hashlib
    from pathlib import Path

    import warp as wp

    from tpnet_gpu.processor.warp_backend import KERNEL_MODULES

    digest = hashlib.sha256()
    for path in sorted((Path(__file__).resolve().parents[2] / "kernels").glob("*.py")):
        digest.update(path.name.encode() + path.read_bytes())
    for module in KERNEL_MODULES:
        assert wp.get_module(module.__name__).options["kernel_sources"] == digest.hexdigest()[:16]


@pytest.mark.parametrize("level", [65535.0, 16383.0], ids=["16-bit", "14-bit"])
def test_issue16_saturated_frames_match_the_reference_or_are_invalid(backend, level):
    # Before: all-saturated mono frames with one dark pixel gave pair peaks of 0.47 where the float64 reference
    # gives 0.0625, on tiles marked valid - the tiles where some camera's window is constant (clipped), whose
    # correlation is float32 rounding noise against the absolute fat zero (tile_processor.md §6.7). Now such
    # tiles are invalid; on the valid ones the result is the reference's within 1e-4 of its peak.
    frames = np.full((4, H, W), level, np.float32)
    frames[:, 13, 20] = 0.0
    tp = TileProcessor(H, W, cfa=None, device="cpu", backend=backend)
    for target in (0.0, 1.5, -2.25, 3.7):
        out = tp.process(frames, target)
        valid = out.valid.numpy()
        centres = out.centres.numpy()
        for t in np.flatnonzero(valid):  # oracle of "featured": every camera's window holds the dark pixel
            corners = np.floor(centres[t] - 8 + 0.5).astype(int)
            assert all(x <= 20 < x + 16 and y <= 13 < y + 16 for x, y in corners)
        want = reference_corr(reference_clt(frames, centres, None), tables.QUAD_PAIRS)[valid]
        assert valid.any()
        assert np.abs(out.corr.numpy()[valid] - want).max() <= 1e-4 * np.abs(want).max()
    flat = tp.process(np.full((4, H, W), level, np.float32), 0.0)  # a flat field: no tile is valid
    assert not flat.valid.numpy().any()
