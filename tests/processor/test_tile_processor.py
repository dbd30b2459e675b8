"""TileProcessor host class: zero-copy hand-off to torch, owned buffers, input handling and bad input.
Oracles: the golden reference (values) and Warp's own buffer pointers (zero-copy)."""

import os
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest
import torch

from tests.allocations import torch_allocations, warp_host_allocations
from tests.kernels.oracle import reference_clt, relative_error
from tpnet_gpu.config import CorrelationConfig
from tpnet_gpu.processor import TileProcessor

H, W = 32, 48


@pytest.fixture
def frames():
    return np.random.default_rng(30).uniform(0, 4000, size=(4, H, W)).astype(np.float32)


def test_results_share_the_warp_buffers(device, backend, frames):
    tp = TileProcessor(H, W, clt=True, device=device, backend=backend)
    out = tp.process(frames, 1.0)
    b = tp._buffers
    assert out.corr.data_ptr() == b.corr.ptr and out.clt.data_ptr() == b.clt.ptr
    assert out.layers.data_ptr() == b.layers.ptr and out.valid.data_ptr() == b.valid.ptr
    assert out.corr.device == tp.torch_device and out.valid.dtype == torch.bool
    again = tp.process(frames, 2.0)  # no allocation per frame: the same buffers again
    assert again.corr.data_ptr() == out.corr.data_ptr()


def test_float32_torch_input_is_read_in_place(device, backend, frames):
    # Oracle: the staging buffer's content. A float32 device tensor is padded from where it lies (the staging
    # buffer keeps its zeros); any other dtype is copied into the staging buffer first.
    tp = TileProcessor(H, W, device=device, backend=backend)
    staging = tp._buffers.frames_t
    tp.load(torch.from_numpy(frames).to(tp.torch_device))
    assert not staging.any()
    tp.load(frames.astype(np.uint16))
    torch.testing.assert_close(staging.cpu(), torch.from_numpy(frames.astype(np.uint16).astype(np.float32)))


def test_measure_without_layers(device, backend, keep_clt, frames):
    """``measure(layers=False)`` makes the same correlations and no layers (``result.layers`` None); a later
    pass with layers makes them as a fresh processor does, masked passes included (tiles an earlier pass left
    layers in and the new one skips are zero). Oracle: a second processor measuring with layers."""
    tp = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    fresh = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    tp.load(frames)
    fresh.load(frames)
    half = np.zeros((H // 8, W // 8), dtype=bool)
    half[:, : W // 16] = True
    tp.measure(1.0)  # layers everywhere, then passes over parts of the frame
    buffer = tp._buffers.result.layers  # the layers' buffer itself: untouched by a pass without them
    for target, active, layers in ((0.5, half, False), (-1.0, ~half, True), (2.0, None, False), (0.0, half, True)):
        before = buffer.clone()
        got = tp.measure(target, active=active, layers=layers)
        want = fresh.measure(target, active=active)
        torch.testing.assert_close(got.corr, want.corr, rtol=0, atol=0)
        if layers:
            torch.testing.assert_close(got.layers, want.layers, rtol=0, atol=0)
        else:
            assert got.layers is None and tp.result.layers is None and torch.equal(buffer, before)
    assert want.layers.abs().sum() > 0 and not want.layers[torch.from_numpy(~half.reshape(-1))].any()


def test_load_pads_with_the_pair_clamp(device, backend, frames):
    """Oracle: the pair clamp of tile_processor.md §1.4 written out in NumPy (an index below 0 takes its parity's
    first row or column, one past the end its parity's last), applied to the frames: the padded buffer equals
    it exactly, borders and interior."""
    from tpnet_gpu.kernels.frames import PAD  # noqa: PLC0415

    def clamp(q, n):
        return np.where(q < 0, q & 1, np.where(q >= n, n - 2 + (q & 1), q))

    tp = TileProcessor(H, W, device=device, backend=backend)
    tp.load(frames)
    rows, cols = clamp(np.arange(H + 2 * PAD) - PAD, H), clamp(np.arange(W + 2 * PAD) - PAD, W)
    padded = tp._buffers.torch(tp._buffers.padded).cpu().numpy()
    np.testing.assert_array_equal(padded, frames[:, rows][:, :, cols])


def test_one_load_serves_many_targets(device, backend, keep_clt, frames):
    # Oracle: process() of the same frames at each target (load once, measure many = the pipeline's passes).
    tp = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    want = [tp.process(frames, d).corr.clone() for d in (0.0, 1.5, -2.0)]
    tp.load(frames)
    for d, expected in zip((0.0, 1.5, -2.0), want):
        torch.testing.assert_close(tp.measure(d).corr, expected, rtol=0, atol=0)


@pytest.mark.parametrize("dtype", [np.uint16, np.float64, np.int32])
def test_any_real_dtype_gives_the_same_result(device, backend, frames, dtype):
    tp = TileProcessor(H, W, clt=True, device=device, backend=backend)
    data = np.round(frames).astype(dtype)
    out = tp.process(data, 0.5)
    want = reference_clt(np.round(frames), out.centres.cpu().numpy(), "GRBG")
    assert relative_error(out.clt, want) <= 1e-5


def test_active_mask_skips_tiles(device, backend, keep_clt, frames):
    tp = TileProcessor(H, W, config=CorrelationConfig(fat_zero=0.0), clt=keep_clt, device=device, backend=backend)
    active = np.zeros((H // 8, W // 8), dtype=bool)
    active[1:3, 1:4] = True
    out = tp.process(frames, 0.0, active=active)
    corr = out.corr.cpu().numpy().reshape(H // 8, W // 8, 6, 15, 15)
    assert np.all(corr[~active] == 0) and np.all(np.abs(corr[active]).max(axis=(1, 2, 3)) > 0)
    np.testing.assert_array_equal(out.valid.cpu().numpy().reshape(active.shape), active)


def test_inactive_tiles_are_zero_after_earlier_passes_wrote_them(device, backend, keep_clt, frames):
    # Oracle: the documented contract (inactive tiles: zero correlations and layers, not valid) and a fresh
    # processor's pass with the same mask and no earlier pass. The fused pass zeroes only the tiles an earlier
    # pass wrote: checked to fail with the mark of an active tile as written left out (stale correlations).
    tp = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend)
    tp.load(frames)
    tp.measure(0.5)  # every tile written
    first = np.zeros((H // 8, W // 8), dtype=bool)
    first[1:3, 1:4] = True
    second = np.zeros_like(first)
    second[0, :] = second[:, 0] = True
    for mask in (first, second, np.zeros_like(first), first):
        out = tp.measure(0.5, active=mask)
        fresh = TileProcessor(H, W, clt=keep_clt, device=device, backend=backend).process(frames, 0.5, active=mask)
        corr, layers = out.corr.cpu().reshape(*mask.shape, -1), out.layers.cpu().reshape(*mask.shape, -1)
        assert not corr[torch.from_numpy(~mask)].any() and not layers[torch.from_numpy(~mask)].any()
        torch.testing.assert_close(out.corr, fresh.corr, rtol=0, atol=0)
        torch.testing.assert_close(out.layers, fresh.layers, rtol=0, atol=0)
        valid = out.valid.cpu().numpy().reshape(mask.shape)
        assert not valid[~mask].any() and np.array_equal(valid, fresh.valid.cpu().numpy().reshape(mask.shape))


def test_two_threads_do_not_crash(frames, backend):
    # Warp CPU tile kernels abort when launched concurrently (platform.md §1); Taichi has one runtime per
    # process. The processor serialises the launches of either backend.
    tps = [TileProcessor(H, W, device="cpu", backend=backend) for _ in range(2)]
    errors = []

    def work(tp):
        try:
            for _ in range(5):
                tp.process(frames, 1.0)
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(tp,)) for tp in tps]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert not errors


def test_off_image_windows_never_read_out_of_bounds_in_debug_mode(tmp_path, backend):
    # Warp's debug mode turns on array bounds checks (an out-of-bounds read aborts the process); Taichi's
    # (TPNET_TAICHI_DEBUG=1) checks every ndarray access and raises.
    script = tmp_path / "debug_run.py"
    script.write_text(textwrap.dedent(f"""
        import numpy as np, warp as wp
        wp.config.mode = "debug"
        from tpnet_gpu.processor import TileProcessor
        rng = np.random.default_rng(0)
        tp = TileProcessor(32, 48, device="cpu", backend="{backend}")
        d = rng.uniform(-200, 200, size=(4, 6)).astype(np.float32)
        d[0, 0] = 1e9
        out = tp.process(rng.uniform(0, 100, size=(4, 32, 48)).astype(np.float32), d)
        assert np.isfinite(out.corr.numpy()).all()
        print("debug-ok", int(out.valid.numpy().sum()))
    """))
    env = {**os.environ, "TPNET_TAICHI_DEBUG": "1"}
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "debug-ok" in done.stdout


def test_default_backend_is_the_measured_faster_one():
    # bench_throughput on 2 cores: Taichi 3.1x Warp for a full frame on the CPU; graphs are Warp's; a small frame
    # is start-up bound, where Warp starts sooner (the next test)
    assert TileProcessor(480, 640, device="cpu").backend == "taichi"
    assert TileProcessor(480, 640, device="cpu", graph=True).backend == "warp"


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(height=30, width=48), ValueError, "height: expected a multiple of 8 that is at least 16, got 30"),
        (dict(height=32, width=8), ValueError, "width: expected a multiple of 8 that is at least 16, got 8"),
        (dict(cfa="RGB"), ValueError, r"cfa: expected one of \['BGGR', 'GBRG', 'GRBG', 'RGGB'\], got 'RGB'"),
        (dict(pairs=[(0, 4)]), ValueError, r"pairs: expected .* distinct integer camera indices in 0..3, got \(0, 4\)"),
        (dict(pairs=[]), ValueError, "pairs: expected at least one"),
        (dict(camera_offsets=[(0, 0, 0)]), ValueError, r"camera_offsets: expected shape \(cams >= 2, 2\)"),
        (dict(kernels=np.zeros((4, 3, 4, 8))), ValueError, r"kernels: expected shape \(cams=4, \[rows >= 1, cols >= 1,\] colours=3"),
        (dict(config=CorrelationConfig(colour_weights=(1.0,))), ValueError, "colour_weights: expected 3 values, got 1"),
        (dict(config=CorrelationConfig(fat_zero=-1.0)), ValueError, "fat_zero: expected a finite number >= 0, got -1.0"),
        (dict(backend="numba"), ValueError, r"backend: expected one of \('warp', 'taichi'\) or None, got 'numba'"),
        (dict(backend="taichi", graph=True), ValueError, "graph: graph capture records Warp launches; it needs "
                                                          "backend='warp', got backend='taichi'"),
    ],
)
def test_bad_construction(kwargs, error, match):
    args = dict(height=H, width=W, device="cpu")
    args.update(kwargs)
    with pytest.raises(error, match=match):
        TileProcessor(args.pop("height"), args.pop("width"), **args)


def test_bad_frames_and_tasks(frames, backend):
    tp = TileProcessor(H, W, device="cpu", backend=backend)
    with pytest.raises(ValueError, match=r"frames: expected shape \(4, 32, 48\) \(cams, height, width\), got \(3, 32, 48\)"):
        tp.process(frames[:3], 0.0)
    with pytest.raises(ValueError, match=r"frames: expected shape \(4, 32, 48\).*got \(4, 48, 32\)"):
        tp.process(np.ascontiguousarray(frames.transpose(0, 2, 1)), 0.0)
    with pytest.raises(TypeError, match="frames: expected real pixel values .* got torch.complex64"):
        tp.process(torch.zeros((4, H, W), dtype=torch.complex64), 0.0)
    with pytest.raises(TypeError, match="frames: expected a torch tensor or numpy array, got list"):
        tp.process([[0.0]], 0.0)
    with pytest.raises(ValueError, match=r"target_disparity: expected shape \(4, 6\) \(tiles_y, tiles_x\), got \(6, 4\)"):
        tp.process(frames, np.zeros((6, 4), dtype=np.float32))
    with pytest.raises(TypeError, match="target_disparity: expected a floating-point dtype, got torch.int64"):
        tp.process(frames, np.zeros((4, 6), dtype=np.int64))
    with pytest.raises(ValueError, match="process: give exactly one of target_disparity and centres"):
        tp.process(frames)
    with pytest.raises(ValueError, match=r"centres: expected shape \(24, 4, 2\)"):
        tp.process(frames, centres=np.zeros((24, 4)))
    with pytest.raises(ValueError, match=r"active: expected a bool mask of shape \(4, 6\) \(tiles_y, tiles_x\) or \(24,\)"):
        tp.process(frames, 0.0, active=np.ones((4, 6), dtype=np.int32))


def test_graph_replay_equals_plain_launches(device):
    # Recorded once, replayed for later frames with new inputs (CUDA graph on the GPU; recorded launches
    # on the CPU). Oracle: the same processor without a graph.
    rng = np.random.default_rng(31)
    plain = TileProcessor(H, W, textures=True, clt=True, graph=False, device=device, backend="warp")
    graphed = TileProcessor(H, W, textures=True, clt=True, graph=True, device=device)
    for _ in range(3):
        frames = rng.uniform(0, 4000, size=(4, H, W)).astype(np.float32)
        disparity = rng.uniform(-3, 3, size=(H // 8, W // 8)).astype(np.float32)
        want = plain.process(frames, disparity)
        got = graphed.process(frames, disparity)
        for name in ("clt", "corr", "layers", "valid", "texture"):
            torch.testing.assert_close(getattr(got, name), getattr(want, name), rtol=0, atol=0)
    assert sorted(graphed._backend.graphs) == [("centres", "convert", "correlate", "layers", "texture"), ("pad",)]


def test_a_frame_allocates_nothing(backend, frames):
    """Issue 14: in steady state a frame's ``load`` + ``measure`` + ``texture`` (numpy frames staged, a tensor
    target) allocates no memory: oracle, torch's CPU allocation events (torch.profiler) and Warp's CPU allocator
    (wrapped), both 0. Checked to fail: a ``torch.empty_like`` of the frames in ``load`` gives 1 event."""
    tp = TileProcessor(H, W, textures=True, device="cpu", backend=backend)
    target = torch.full((tp.tiles_y, tp.tiles_x), 1.5)

    def frame():
        tp.load(frames)
        tp.measure(target)
        tp.texture()

    frame()
    frame()  # warm-up: kernels compiled, views made
    with warp_host_allocations() as warp_sizes:
        torch_sizes = torch_allocations(frame)
    assert torch_sizes == [] and warp_sizes == []


def test_clt_tiles_are_kept_only_when_asked(backend, frames):
    # Oracle: the processor's documented contract (tile_processor.py docstring): no CLT buffer for the fused pass.
    fused = TileProcessor(H, W, device="cpu", backend=backend)
    assert fused._buffers.clt is None and fused.process(frames, 1.0).clt is None
    with pytest.raises(RuntimeError, match="clt=True"):
        fused.convert()
    textured = TileProcessor(H, W, textures=True, device="cpu", backend=backend)  # converts band by band
    assert textured._buffers.clt is None and textured.process(frames, 1.0).clt is None
    assert TileProcessor(H, W, clt=True, device="cpu", backend=backend).result.clt is not None


def test_texture_after_a_fused_measure_converts_first(backend, frames):
    """A texturing processor measures fused (no CLT writes) and converts at the current targets when the
    texture asks. Oracle: the float64 reference's correlations and the texture ``process`` makes, which the
    reference tests check against the float64 reference; the texture of the same targets after a fused measure
    at other targets must be that one (a stale CLT would give the other targets' texture)."""
    tp = TileProcessor(H, W, textures=True, device="cpu", backend=backend)
    want = tp.process(frames, 1.5).texture.clone()
    tp.load(frames)
    tp.measure(0.0)  # fused, at other targets
    tp.set_targets(1.5)
    tp.texture()
    torch.testing.assert_close(tp.result.texture, want, rtol=0, atol=1e-5)
    tp.measure(0.0)
    tp.texture()
    assert (tp.result.texture - want).abs().max() > 1e-3  # the targets' own texture, not a stale one


def test_taichi_rejects_buffers_with_unaligned_rows():
    """Taichi's vector loads assume rows of 8 or 16 floats aligned on their size (an unaligned one faults): the
    backend checks each array once, by address. Oracle: the address arithmetic of a view 4 bytes into its storage.
    Checked to fail: without the check the view is taken and no error is raised."""
    import warp as wp

    tp = TileProcessor(H, W, device="cpu", backend="taichi")
    storage = torch.zeros(4 * 8 + 16)
    aligned = wp.from_torch(storage[: 4 * 8].view(4, 8))
    assert tp._backend._v(aligned).data_ptr() == storage.data_ptr()
    with pytest.raises(RuntimeError, match="not aligned on its rows of 32 bytes"):
        tp._backend._v(wp.from_torch(storage[1 : 1 + 4 * 8].view(4, 8)))


def test_the_default_backend_follows_the_frame_size():
    """docs/platform.md §4 (config.SMALL_FRAME_PIXELS): on the CPU a frame of at most 320x240 pixels gets Warp
    (start-up bound), a larger one Taichi; an explicit backend wins. The CLI passes --backend as given."""
    assert TileProcessor(240, 320, device="cpu").backend == "warp"
    assert TileProcessor(240, 328, device="cpu").backend == "taichi"
    assert TileProcessor(240, 320, device="cpu", backend="taichi").backend == "taichi"
