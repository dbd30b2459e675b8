"""The throughput bench's report: the per-stage table with ratios and frames/s, the targets, and the printed
summary (table, agreement, graph replay, the paper's figures beside ours)."""

from __future__ import annotations

import re

from tpnet_gpu.bench.common import format_table, summary
from tpnet_gpu.bench.throughput.throughput_common import AGREEMENT_TOL

# Filippov & Dzhimiev, "See far with TPNET", on a GTX 1050 Ti, one full quad frame (as quoted in the issue):
# the whole TP 87 ms; the network 0.46 + 0.12 s (listed here beside our stage 1 and stage 2).
PAPER_NETWORK_S = (0.46, 0.12)
TARGET_GPU = "H100"
TARGET_TP_MS = 1.0
TARGET_TP_NET_MS = 3.0
TARGET_CPU_RATIO = 2.0
FULL_FRAME = (1936, 2592)

# Table rows: (name, whole frame?). Each implementation maps the names it runs to a callable ``fn()``.
ROWS = (
    ("convert", False),
    ("correlate", False),
    ("texture", False),  # Warp and Taichi only: no twin (the float64 reference is the oracle)
    ("network stage 1", False),  # the network rows: one PyTorch model, listed under warp
    ("network stage 2", False),
    ("network whole frame", True),
    ("TP whole frame", True),
    ("TP fused whole frame", True),  # prepare + the fused pass (what measure runs without kept CLT tiles)
    ("TP+network whole frame", True),
)


def stage_table(runs: dict, warmups: dict, impls: tuple) -> list[dict]:
    """One entry per row of ``ROWS``: per implementation the run summary and warm-up, the ratio to Warp, and
    frames/s for the whole-frame rows."""
    table = []
    for name, whole_frame in ROWS:
        entry = {"name": name, "whole_frame": whole_frame}
        for impl in impls:
            entry[f"{impl}_ms"] = summary(runs[impl][name]) if name in runs.get(impl, {}) else None
            entry[f"{impl}_warmup_ms"] = warmups.get(impl, {}).get(name)
        for impl in impls[1:]:
            peer = entry[f"{impl}_ms"]
            entry[f"ratio_{impl}_over_warp"] = peer["median"] / entry["warp_ms"]["median"] if peer else None
        entry["fps"] = {impl: 1e3 / entry[f"{impl}_ms"]["median"] for impl in impls
                        if whole_frame and entry[f"{impl}_ms"]} or None
        table.append(entry)
    return table


def _cpu_target(what: str, ratio: float | None, applies: bool, is_cuda: bool) -> dict:
    return {
        "target": f"on CPU: {what} >= {TARGET_CPU_RATIO:g}x the vectorised NumPy one (TP whole frame)",
        "ours_ratio": ratio,
        "met": (ratio >= TARGET_CPU_RATIO) if applies and ratio is not None else None,
        "not_applicable": None if applies else ("CPU runs only" if is_cuda else "needs the full 2592x1936 frame"),
    }


def targets(table: list[dict], graph: dict, gpu_name: str, is_cuda: bool, frame: tuple[int, int]) -> dict:
    """The issue's targets against this run: TP and TP+network on an H100 (the processor's best path, graph replay
    included), and on the CPU the Warp path and the default backend (Taichi on every core) against NumPy."""
    by_name = {e["name"]: e for e in table}
    tp_ms = by_name["TP whole frame"]["warp_ms"]["median"]
    tp_net_ms = by_name["TP+network whole frame"]["warp_ms"]["median"]
    if graph["available"]:  # the processor's best path: process() with graph replay
        tp_ms = min(tp_ms, graph["graph_process_ms"]["median"])
        tp_net_ms = min(tp_net_ms, graph["graph_process_network_ms"]["median"])
    full_frame = tuple(frame) == FULL_FRAME
    out = {
        "gpu_tp": {"target": f"on an {TARGET_GPU}: TP <= {TARGET_TP_MS:g} ms per quad frame", "ours_ms": tp_ms,
                   "ours_is": "best of the stage launches and process() with graph replay"},
        "gpu_tp_network": {"target": f"on an {TARGET_GPU}: TP+network <= {TARGET_TP_NET_MS:g} ms per quad frame",
                           "ours_ms": tp_net_ms,
                           "ours_is": "best of the stage launches and process() with graph replay, + forward_frame"},
    }
    applies = is_cuda and TARGET_GPU in gpu_name and full_frame
    why = None if applies else ("needs a CUDA run on an H100" if not (is_cuda and TARGET_GPU in gpu_name)
                                else "needs the full 2592x1936 frame")
    for key, limit in (("gpu_tp", TARGET_TP_MS), ("gpu_tp_network", TARGET_TP_NET_MS)):
        out[key]["met"] = (out[key]["ours_ms"] <= limit) if applies else None
        out[key]["not_applicable"] = why
    tp_row = by_name["TP whole frame"]
    cpu_applies = not is_cuda and full_frame
    out["cpu_warp_vs_numpy"] = _cpu_target("Warp path", tp_row["ratio_numpy_over_warp"], cpu_applies, is_cuda)
    # the CPU default backend (TileProcessor(backend=None) on the CPU is Taichi on every core) against NumPy
    threads = {c: int(m.group(1)) for c in tp_row if tp_row[c] and (m := re.fullmatch(r"taichi-(\d+)t_ms", c))}
    fastest = max(threads, key=threads.get, default=None)  # the most threads: the default uses every core
    if fastest is not None and tp_row["numpy_ms"]:
        ratio = tp_row["numpy_ms"]["median"] / tp_row[fastest]["median"]
        out["cpu_default_vs_numpy"] = _cpu_target(f"the default backend ({fastest[:-3]})", ratio, cpu_applies, is_cuda)
    return out


def print_report(report: dict) -> None:
    f, t, d = report["frame"], report["timing"], report["device"]

    def ms(x):
        if x is None:
            return "-"
        return f"{x['median']:.3f}" if x["median"] < 10 else f"{x['median']:.1f}"

    def ratio(x):
        return "-" if x is None else f"{x:.2f}"

    print(f"Throughput, {f['width']}x{f['height']}, {f['cameras']} cameras ({f['cfa'] or 'mono'}), {f['tiles']} tiles, "
          f"{f['pairs']} pairs")
    print(f"device: {d['warp_device']} = {d['name']}; torch threads {report['machine']['torch_threads']}; "
          f"median of {t['repeat']} back-to-back runs after a warm-up call, per row")
    taichi = [c for c in report["columns"] if c.startswith("taichi")]
    rows = [(s["name"], ms(s["warp_ms"]), ms(s["numpy_ms"]), ms(s["torch_ms"]), *(ms(s[f"{c}_ms"]) for c in taichi),
             ratio(s["ratio_numpy_over_warp"]), ratio(s["ratio_torch_over_warp"]),
             *(ratio(s[f"ratio_{c}_over_warp"]) for c in taichi), f"{s['fps']['warp']:.2f}" if s["fps"] else "-")
            for s in report["stages"]]
    header = ("stage", "warp ms", "numpy ms", "torch ms", *(f"{c} ms" for c in taichi), "numpy/warp", "torch/warp",
              *(f"{c}/warp" for c in taichi), "fps (warp)")
    print("\n".join(format_table(header, rows)))
    print("network rows: the same PyTorch TPNet for every path, on the processor's device (listed under warp); "
          "whole-frame twins: their TP, then torch_layers + that network")
    fps = {s["name"]: s["fps"] for s in report["stages"] if s["fps"]}
    for name in ("TP whole frame", "TP+network whole frame"):
        print(f"frames/s, {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in fps[name].items()))
    for impl, a in report["agreement"].items():
        if isinstance(a, dict):
            print(f"{impl} vs warp, max relative difference (elements > {AGREEMENT_TOL:g} max |warp|): " + ", ".join(
                f"{k} {v['max_rel_diff']:.2e} ({v['elements_over_tol']} of {v['elements']})" for k, v in a.items()))
    if any(isinstance(a, dict) and a["layers"]["elements_over_tol"] for a in report["agreement"].values()):
        print(f"  layers: {report['agreement']['layers_note']}")
    print(f"network split (stage 1 -> stage 2) vs forward_frame, max abs difference: "
          f"{report['agreement']['network_split_vs_forward_frame_max_abs_diff']:.2e}")
    g = report["graph_replay"]
    if g["available"]:
        print(f"graph replay ({g['kind']}, TileProcessor({g['option']}=True)): process() "
              f"{g['plain_process_ms']['median']:.3f} ms plain -> {g['graph_process_ms']['median']:.3f} ms replayed, "
              f"gain {g['gain']:.2f}x; replay + network {g['graph_process_network_ms']['median']:.3f} ms")
    else:
        print(f"graph replay gain: {g['note']}")
    p = report["paper"]
    by_name = {s["name"]: s for s in report["stages"]}
    ours = {k: by_name[k]["warp_ms"]["median"] for k in
            ("TP whole frame", "network stage 1", "network stage 2", "network whole frame", "TP+network whole frame")}
    print(f"paper ({p['gpu']}, full quad frame): TP {p['tp_ms']:.0f} ms, network {p['network_s'][0]:.2f} + "
          f"{p['network_s'][1]:.2f} s = {sum(p['network_s']):.2f} s, TP+network "
          f"{p['tp_ms'] / 1e3 + sum(p['network_s']):.3f} s")
    print(f"ours ({d['name']}, {f['width']}x{f['height']}): TP {ours['TP whole frame']:.4g} ms, network stage 1 + "
          f"stage 2 {ours['network stage 1']:.4g} + {ours['network stage 2']:.4g} ms (whole frame "
          f"{ours['network whole frame']:.4g} ms), TP+network {ours['TP+network whole frame']:.4g} ms"
          + ("" if d["is_cuda"] else " [CPU: not comparable with the paper's GPU figures]"))
    fl = report["floor"]
    print(f"floor ({fl['gpu']['name']}: {fl['gpu']['source']}; counting: {fl['counting']}): " + ", ".join(
        f"{name} {r['floor_ms']:.3g} ms ({r['bytes'] / 1e9:.3f} GB, {r['flops'] / 1e9:.2f} GFLOP, {r['bound']} bound;"
        f" ours / floor {ours[name] / r['floor_ms']:.0f}x)" for name, r in fl["rows"].items()))
    for target in report["targets"].values():
        value = target.get("ours_ms")
        got = f"ours {value:.3f} ms" if value is not None else (
            f"ours {target['ours_ratio']:.2f}x" if target.get("ours_ratio") is not None else "ours -")
        verdict = ("MET" if target["met"] else "NOT MET") if target["met"] is not None else \
            f"n/a ({target['not_applicable']})"
        print(f"target: {target['target']}: {got} -> {verdict}")
    s = report["soak"]
    if s:
        print(f"soak: {s['frames']} frames of {s['size']['width']}x{s['size']['height']} through process() + "
              f"forward_frame at {s['frames_per_s']:.1f} frames/s; RSS first {s['first_rss_kib'] / 1024:.1f} MiB "
              f"(after frame 1), last {s['last_rss_kib'] / 1024:.1f} MiB, growth {s['growth_kib'] / 1024:+.1f} MiB "
              f"(max {s['max_rss_kib'] / 1024:.1f} MiB; after frame 100: "
              f"{s['steady_slope_kib_per_1000_frames'] / 1024:+.2f} MiB per 1000 frames)")
        print("soak RSS MiB by frame: " + ", ".join(f"{x['frame']}: {x['rss_kib'] / 1024:.1f}" for x in s["samples"]))
