"""Shared by the throughput bench's runs (bench_throughput.py and its helpers): the progress log, the per-stage
timing loop and the comparison of outputs with the Warp processor's (timing and the log itself: common.py)."""

from __future__ import annotations

from typing import Callable

import torch

from tpnet_gpu.bench import common
from tpnet_gpu.bench.common import timed_ms

StageFns = dict[str, Callable[[], None]]
AGREEMENT_TOL = 1e-4  # relative to max |warp|, as the twins' tests against the reference


log = common.logger("bench_throughput")  # the throughput modules all log as the bench


def run_stages(label: str, stages: StageFns, sync: Callable[[], None] | None, repeat: int) -> tuple[dict, dict]:
    """Each stage in order (later stages may read earlier stages' outputs): one warm-up call, then ``repeat``
    back-to-back timed calls (the steady state of a stream of frames: the first call after another stage pays
    for cold caches, fresh allocations and idle thread pools). Returns (warm-up ms, run ms lists) by name."""
    warmup, runs = {}, {}
    for name, fn in stages.items():
        warmup[name] = timed_ms(fn, sync)
        runs[name] = [timed_ms(fn, sync) for _ in range(repeat)]
        log(f"{label} {name}: warm-up {warmup[name]:.1f} ms, runs " + ", ".join(f"{t:.1f}" for t in runs[name]) + " ms")
    return warmup, runs


def agreement(got, want: torch.Tensor) -> dict:
    """max |got - want| / max |want| and the number of elements with |got - want| > 1e-4 max |want|, one camera or
    pair (axis 1) at a time (no full-size temporaries)."""
    got = torch.as_tensor(got).to(want.device)
    scale = max(float(want.max()), -float(want.min())) or 1.0
    diff, over = 0.0, 0
    for i in range(want.shape[1]):
        d = (got[:, i] - want[:, i]).abs()
        diff = max(diff, float(d.max()))
        over += int((d > AGREEMENT_TOL * scale).sum())
    return {"max_rel_diff": diff / scale, "elements_over_tol": over, "elements": want.numel()}
