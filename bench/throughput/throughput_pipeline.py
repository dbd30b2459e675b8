"""The throughput bench's pipeline rows: ``Pipeline.process`` per whole frame and per stage, one tile-processor
pass beside the plain-PyTorch-ops twin on the same device, the paper's figures and the H200 floor.

Per frame size (``--pipeline-sizes``, default 640x480; add 2592x1936 for the full frame: ~30 s and ~7 GB on the
CPU): one quad frame (the rendered demo scene, or random raw values), ``Pipeline(backend=--pipeline-backend)``
built once, one warm-up frame, then ``--pipeline-frames`` frames timed whole (nothing added to the call) and as
many again with stage clocks. The stages come from the pipeline's own parts, without a second copy of its loop:
the clock wraps, on these instances only, the engine's ``search`` and ``run``, the network inference
(``Pipeline._infer``) and the texture processor's ``texture`` with a device synchronisation and a timestamp at
their end. So per frame: **engine search** = start -> end of ``search`` (normalise, load, first stage),
**engine refine** = -> end of ``run`` (refinement + consistency), **network** = -> end of the last inference
(each pass's re-correlation and TPNET), **texture** = -> end of ``texture`` (targets, convert, texture), and
**rest** = -> the return (confidence, result). Medians over frames.

Beside it, on the same frame: one full-frame tile-processor pass at the engine's first-stage answer (centres,
convert, correlate with layers: ``DisparityEngine.measure_at``) and the torch twin's convert + correlate +
``torch_layers`` at the same tile centres (their correlations compared), the frame's floor on the H200
(throughput_floor.py), on the CPU that pass against this CPU's FP32 roofline (``throughput_floor.cpu_peak``), and
OpenCV StereoSGBM on two cameras of the same frame timed in the same run (the ratio: what a user would run
instead).
"""

from __future__ import annotations

import contextlib
import gc
import time

import numpy as np
import torch
import warp as wp

from tpnet_gpu import tables
from tpnet_gpu.camera import Rig
from tpnet_gpu.pipeline import Pipeline

from tpnet_gpu.bench import common
from tpnet_gpu.bench.common import PAPER_GPU, PAPER_TP_MS, format_table, random_frames, summary, timed_ms
from tpnet_gpu.bench.throughput.throughput_common import agreement, log
from tpnet_gpu.bench.throughput.throughput_floor import H200, cpu_peak, floor, network_work, pipeline_work, tp_pass, \
    tp_steps
from tpnet_gpu.bench.throughput.throughput_report import PAPER_NETWORK_S
from tpnet_gpu.bench.twins.torch_tp import torch_convert, torch_correlate, torch_layers

STAGES = ("engine search", "engine refine", "network", "texture", "rest")
SCENES = ("demo", "random")
FULL_SIZE = (2592, 1936)


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``--pipeline-sizes``: ``"640x480,2592x1936"`` -> [(640, 480), (2592, 1936)] (width x height); '' -> []."""
    return common.parse_sizes(text, "--pipeline-sizes")


def scene_frames(width: int, height: int, scene: str, seed: int) -> np.ndarray:
    """``(4, height, width)`` float32 quad frames: the demo scene rendered (black level subtracted), or random."""
    if scene == "random":
        return random_frames(np.random.default_rng(seed), height, width)
    from tpnet_gpu.scenes import Sensor, demo_scene, render  # noqa: PLC0415 - rendering only when asked

    rig = Rig(width=width, height=height)
    rendered = render(demo_scene(rig, seed=seed), rig, sensor=Sensor(), supersample=1, seed=seed)
    return rendered.raws.astype(np.float32) - rendered.sensor.black_level


class StageClock:
    """Timestamps at the end of the pipeline's parts during ``Pipeline.process`` (see the module docstring)."""

    def __init__(self, pipe: Pipeline, sync):
        self.pipe, self.sync = pipe, sync
        self.marks: list[tuple[str, float]] = []
        self.result = None  # the last clocked frame's FrameResult
        texture_tp = pipe.network_tp if pipe.model is not None else pipe.engine.tp
        self.parts = [(pipe.engine, "search", "engine search"), (pipe.engine, "run", "engine refine"),
                      (texture_tp, "texture", "texture")]
        if pipe.model is not None:
            self.parts.append((pipe, "_infer", "network"))

    @contextlib.contextmanager
    def hooked(self):
        """The wrapped parts while inside (instance attributes shadowing the methods), restored on exit."""
        saved = []
        for obj, name, label in self.parts:
            original = getattr(obj, name)
            saved.append((obj, name, name in vars(obj), original))
            setattr(obj, name, self._timed(original, label))
        try:
            yield self
        finally:
            for obj, name, own, original in saved:
                if own:
                    setattr(obj, name, original)
                else:
                    delattr(obj, name)

    def _timed(self, fn, label: str):
        def timed(*args, **kwargs):
            out = fn(*args, **kwargs)
            self.sync()
            self.marks.append((label, time.perf_counter()))
            return out

        return timed

    def frame(self, frames) -> dict[str, float]:
        """One ``process(frames)``: ms per stage (``STAGES``; 0 for a stage the frame has not got); its result is
        kept in ``self.result``."""
        self.marks = []
        self.sync()
        start = time.perf_counter()
        self.result = self.pipe.process(frames)
        self.sync()
        self.marks.append(("rest", time.perf_counter()))
        out, last = dict.fromkeys(STAGES, 0.0), start
        for label, at in self.marks:  # network: several inference calls add up
            out[label] += 1e3 * (at - last)
            last = at
        return out


def _tp_pass_rows(pipe: Pipeline, frames_t: torch.Tensor, target: torch.Tensor, sync, repeat: int) -> dict:
    """One full-frame pass of the engine's processor at ``target`` and the torch twin's at the same centres."""
    engine, tp = pipe.engine, pipe.engine.tp
    cfg = tp.config
    runs = [timed_ms(lambda: engine.measure_at(tp, target), sync) for _ in range(repeat + 1)][1:]
    centres, want = tp.result.centres.clone(), tp.result.corr.clone()
    normalised = engine.normalise(frames_t)  # what the engine's processor was loaded with
    state = {}

    def twin() -> None:
        state["corr"] = None  # the previous output first: at full frame the CLT alone is ~1 GB
        clt = torch_convert(normalised, centres, tp.cfa)
        state["corr"] = torch_correlate(clt, tp.pairs, cfg.colour_weights, cfg.fat_zero, cfg.sigma_rb, cfg.sigma_corr)
        del clt
        state["layers"] = torch_layers(state["corr"], cfg.net_offset) if tp.pairs == tables.QUAD_PAIRS else None

    twin_runs = [timed_ms(twin, sync) for _ in range(repeat + 1)][1:]
    agree = agreement(state["corr"], want)
    state.clear()
    ours, twin_ms = summary(runs), summary(twin_runs)
    return {"processor_ms": ours, "torch_twin_ms": twin_ms,
            "ratio_torch_over_processor": twin_ms["median"] / ours["median"],
            "corr_agreement": agree,
            "what": "centres + convert + correlate (+ layers) of every tile at the engine's first-stage answer; the "
                    "twin: torch_convert + torch_correlate + torch_layers at the same tile centres"}


def _sgbm_row(frames_t: torch.Tensor, max_disparity: float, repeat: int) -> dict | None:
    """OpenCV StereoSGBM (``twins/peers.py``) on cameras 0 and 1 of the same frame (the quad's top pair, a
    horizontal baseline), over the pipeline's disparity range: what a user would run instead, timed in the same run
    (its accuracy is not compared here). None without OpenCV (the ``bench`` extra)."""
    try:
        import cv2  # noqa: F401, PLC0415 - only to know it is there
    except ModuleNotFoundError:
        return None
    from tpnet_gpu.bench.twins import peers  # noqa: PLC0415

    left, right = (frames_t[cam].detach().cpu().numpy() for cam in (0, 1))
    reach = min(float(max_disparity), left.shape[1] / 2 - 8)  # SGBM's range must fit the image's width
    runs = [timed_ms(lambda: peers.sgbm(left, right, reach)) for _ in range(repeat + 1)][1:]
    return {"ms": summary(runs), "max_disparity": reach,
            "what": "cv2 StereoSGBM 3WAY, block 5, cameras 0 and 1 as 8-bit images, the pipeline's range (at most "
                    "half the width)"}


def _roofline(work, measured_ms: float) -> dict:
    """One TP pass against this CPU's FP32 peak (``cpu_peak``): its floor and the share of the peak it reached."""
    peak = cpu_peak()
    floor_ms = 1e3 * work.flops / peak["fp32_flops_per_s"]
    return {**peak, "tp_pass_gflop": work.flops / 1e9, "tp_pass_floor_ms": floor_ms,
            "share_of_peak": floor_ms / measured_ms}


def run_pipeline(width: int, height: int, args, device, sync) -> dict:
    """The pipeline rows of one frame size (see the module docstring)."""
    frames = scene_frames(width, height, args.pipeline_scene, args.seed)
    start = time.perf_counter()
    pipe = Pipeline(height, width, device=str(device), backend=args.pipeline_backend)
    build_ms = 1e3 * (time.perf_counter() - start)
    frames_t = torch.from_numpy(frames).to(pipe.device)
    del frames
    label = f"pipeline {width}x{height}"
    with torch.inference_mode():
        warmup_ms = timed_ms(lambda: pipe.process(frames_t), sync)
        log(f"{label}: built in {build_ms:.0f} ms, warm-up frame {warmup_ms:.0f} ms")
        whole = [timed_ms(lambda: pipe.process(frames_t), sync) for _ in range(args.pipeline_frames)]
        log(f"{label}: frames " + ", ".join(f"{t:.1f}" for t in whole) + " ms")
        clock = StageClock(pipe, sync)
        with clock.hooked():
            staged = [clock.frame(frames_t) for _ in range(args.pipeline_frames)]
        result = clock.result
        tile_passes = float(result.tile_passes)
        tp_rows = _tp_pass_rows(pipe, frames_t, result.search.clone(), sync, args.pipeline_frames)
    peer = _sgbm_row(frames_t, pipe.engine.d_max, args.pipeline_frames)
    tp = pipe.engine.tp
    steps = tp_steps(height, width, tp.cams, tp.colours, len(tp.pairs), tp.pairs == tables.QUAD_PAIRS)
    net = network_work(pipe.model, tp.tiles) if pipe.model is not None else None
    network_passes = pipe.config.network_passes if net is not None else 0
    textures = pipe.config.textures
    passes = tile_passes + network_passes
    report = {
        "size": {"width": width, "height": height}, "tiles": tp.tiles, "cameras": tp.cams,
        "backend": tp.backend, "scene": args.pipeline_scene, "frames": args.pipeline_frames,
        "build_ms": build_ms, "warmup_ms": warmup_ms,
        "process_ms": summary(whole), "fps": 1e3 / summary(whole)["median"],
        "stages_ms": {name: summary([s[name] for s in staged]) for name in STAGES},
        "staged_frame_ms": summary([sum(s.values()) for s in staged]),
        "tile_passes": tile_passes, "network_passes": network_passes, "textures": textures,
        "tp_pass": tp_rows,
        "twin_tp_estimate_ms": passes * tp_rows["torch_twin_ms"]["median"],
        "twin_tp_estimate_note": f"(engine tile_passes + network passes) = {passes:.2f} full-frame passes at the "
                                 f"torch twin's speed: the tile-processor work of a frame, had it no masked passes",
        "sgbm": peer,
        "sgbm_ratio": None if peer is None else summary(whole)["median"] / peer["ms"]["median"],
        "cpu_roofline": None if device.is_cuda else _roofline(tp_pass(steps), tp_rows["processor_ms"]["median"]),
        "floor": {"gpu": H200["name"], "tp_pass": floor(tp_pass(steps)),
                  "network": floor(net) if net is not None else None,
                  "frame": floor(pipeline_work(steps, net, tile_passes, network_passes, textures))},
    }
    del pipe, clock, result, frames_t
    gc.collect()
    return report


def run_all(args, device, tdev: torch.device) -> dict:
    """Every size of ``--pipeline-sizes``; the ``pipeline`` entry of the report."""
    def sync() -> None:
        wp.synchronize_device(device)
        if tdev.type == "cuda":
            torch.cuda.synchronize(tdev)

    rows = []
    for width, height in args.pipeline_sizes:
        log(f"pipeline {width}x{height} ({args.pipeline_scene} frames, backend {args.pipeline_backend or 'default'})"
            " ...")
        rows.append(run_pipeline(width, height, args, device, sync))
    return {"rows": rows, "stages": list(STAGES),
            "paper": {"gpu": PAPER_GPU, "size": {"width": FULL_SIZE[0], "height": FULL_SIZE[1]},
                      "tp_ms": PAPER_TP_MS, "network_ms": 1e3 * sum(PAPER_NETWORK_S),
                      "note": "the paper's whole TP and network per full quad frame (its own pipeline, not this one)"},
            "floor_gpu": H200,
            "timing": "median over --pipeline-frames frames after one warm-up frame; whole frames unclocked, stages "
                      "from a second set of frames with a device synchronisation at the end of each stage"}


def print_pipeline(section: dict, device_name: str) -> None:
    """The pipeline table, the paper's reference row and the H200 floor row."""
    def ms(x) -> str:
        value = x["median"] if isinstance(x, dict) else x
        return f"{value:.2e}" if value < 0.01 else f"{value:.3f}" if value < 10 else f"{value:.1f}"

    rows = []
    for r in section["rows"]:
        size = f"{r['size']['width']}x{r['size']['height']}"
        rows.append((f"{size} ({device_name}, {r['backend']})", ms(r["process_ms"]), f"{r['fps']:.2f}",
                     *(ms(r["stages_ms"][s]) for s in STAGES), f"{r['tile_passes']:.2f}",
                     ms(r["tp_pass"]["processor_ms"]), ms(r["tp_pass"]["torch_twin_ms"]),
                     f"{r['tp_pass']['ratio_torch_over_processor']:.2f}", ms(r["twin_tp_estimate_ms"]),
                     "-" if r["sgbm"] is None else ms(r["sgbm"]["ms"]),
                     "-" if r["sgbm_ratio"] is None else f"{r['sgbm_ratio']:.1f}"))
    p = section["paper"]
    rows.append((f"paper {p['size']['width']}x{p['size']['height']} ({p['gpu']})", ms(p["tp_ms"] + p["network_ms"]),
                 f"{1e3 / (p['tp_ms'] + p['network_ms']):.2f}", "-", "-", ms(p["network_ms"]), "-", "-", "-",
                 ms(p["tp_ms"]), "-", "-", "-", "-", "-"))
    for r in section["rows"]:
        f = r["floor"]
        net = f["network"]["floor_ms"] if f["network"] else 0.0
        rows.append((f"{r['size']['width']}x{r['size']['height']} floor ({section['floor_gpu']['name']})",
                     ms(f["frame"]["floor_ms"]), f"{1e3 / f['frame']['floor_ms']:.0f}", "-", "-", ms(net), "-", "-",
                     "-", ms(f["tp_pass"]["floor_ms"]), "-", "-", "-", "-", "-"))
    header = ("Pipeline.process", "frame ms", "fps", *(f"{s} ms" for s in STAGES), "tile passes", "TP pass ms",
              "twin pass ms", "twin/ours", "twin TP est. ms", "SGBM ms", "ours/SGBM")
    print("\n".join(format_table(header, rows)))
    print(f"pipeline: {section['timing']}; TP pass = one full-frame pass of the engine's processor (the "
          f"project's kernels in the pipeline's backend; twin: plain PyTorch ops on the same device); twin TP est. = the frame's passes at "
          f"the twin's speed; paper row: its TP in the TP column and its network in the network column")
    for r in section["rows"]:
        f, a = r["floor"]["frame"], r["tp_pass"]["corr_agreement"]
        print(f"floor {r['size']['width']}x{r['size']['height']}: {f['bytes'] / 1e9:.3f} GB and {f['flops'] / 1e9:.2f} "
              f"GFLOP per frame -> {f['memory_ms']:.3f} ms at {section['floor_gpu']['hbm_bytes_per_s'] / 1e12:g} TB/s, "
              f"{f['compute_ms']:.3f} ms at {section['floor_gpu']['fp32_flops_per_s'] / 1e12:g} TFLOPS FP32 "
              f"({f['bound']} bound); measured / floor {r['process_ms']['median'] / f['floor_ms']:.0f}x; twin vs "
              f"processor corr max relative difference {a['max_rel_diff']:.2e}")
        roof = r["cpu_roofline"]
        if roof is not None:
            print(f"CPU roofline {r['size']['width']}x{r['size']['height']}: one TP pass {roof['tp_pass_gflop']:.2f} "
                  f"GFLOP; {roof['name']}, {roof['cores']} cores x {roof['ghz']:.2f} GHz x "
                  f"{roof['fp32_flops_per_cycle']} FP32 FLOP/cycle = {roof['fp32_flops_per_s'] / 1e9:.0f} GFLOPS -> "
                  f"{roof['tp_pass_floor_ms']:.1f} ms; measured {r['tp_pass']['processor_ms']['median']:.1f} ms = "
                  f"{100 * roof['share_of_peak']:.0f} % of the peak")
    if any(r["sgbm"] is not None for r in section["rows"]):
        print("SGBM: " + next(r["sgbm"]["what"] for r in section["rows"] if r["sgbm"] is not None)
              + "; ours/SGBM = the whole frame's time over SGBM's on two of its cameras")
