"""Counting the memory a call allocates: torch's CPU allocations (torch.profiler's memory events, one per
allocation, with its size) and Warp's host allocations (its CPU allocator, wrapped while the call runs)."""

from __future__ import annotations

import contextlib

import warp as wp
from torch.profiler import ProfilerActivity, profile


@contextlib.contextmanager
def warp_host_allocations():
    """Yields a list that collects the byte count of every Warp CPU allocation made inside the block."""
    allocator = type(wp.get_device("cpu").get_allocator())
    sizes, original = [], allocator.allocate

    def counting(self, size_in_bytes):
        sizes.append(size_in_bytes)
        return original(self, size_in_bytes)

    allocator.allocate = counting
    try:
        yield sizes
    finally:
        allocator.allocate = original


def torch_allocations(fn) -> list[int]:
    """The byte counts of the torch CPU allocations ``fn()`` makes (frees left out), in order."""
    with profile(activities=[ProfilerActivity.CPU], profile_memory=True) as prof:
        fn()
    events = prof.profiler.kineto_results.events()
    return [e.nbytes() for e in events if e.name() == "[memory]" and e.nbytes() > 0]
