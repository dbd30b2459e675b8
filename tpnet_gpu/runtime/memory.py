"""Memory the machine can give a run, and the refusal when the work would need more (issue 40: a 4000x3000 pair
searched to 2000 px passed 8 GB in 46 s with no refusal, the OOM killer's job on a smaller machine).

``available_bytes(device)``: what a new allocation can get - on CUDA the free device memory, on the CPU the
kernel's MemAvailable, capped by the process's cgroup limit (a container's) where one is set. ``limit_bytes``:
the budget of one run - ``memory_limit_gb`` when given, else ``DEFAULT_SHARE`` of what is available.
``check(need, ...)`` refuses, in the time it takes to read two files, work that the budget cannot hold.
"""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_SHARE = 0.8  # of the memory available when the run starts: the rest for the OS, the caches, Python
GB = 1e9


def _meminfo_available() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_room() -> float | None:
    """What the process's cgroup (v2) still allows, or None where it sets no limit."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = float(Path("/sys/fs/cgroup/memory.current").read_text().strip())
    except (OSError, ValueError):
        return None
    return None if limit == "max" else max(float(limit) - used, 0.0)


def available_bytes(device: str = "cpu") -> float | None:
    """Bytes a new allocation on ``device`` ("cpu" or "cuda...") can get now; None where it cannot be told."""
    if str(device).startswith("cuda"):
        import torch  # noqa: PLC0415 - only for a CUDA run

        if not torch.cuda.is_available():  # the tile processor refuses the device, naming it
            return None
        free, _ = torch.cuda.mem_get_info(torch.device(device))
        return float(free)
    room = [v for v in (_meminfo_available(), _cgroup_room()) if v is not None]
    return min(room) if room else None


def limit_bytes(memory_limit_gb: float | None, device: str = "cpu") -> float | None:
    """The run's budget: ``memory_limit_gb`` (GB) when given, else ``DEFAULT_SHARE`` of ``available_bytes``."""
    if memory_limit_gb is not None:
        return float(memory_limit_gb) * GB
    free = available_bytes(device)
    return None if free is None else DEFAULT_SHARE * free


def check(need: float, memory_limit_gb: float | None, device: str, what: str) -> None:
    """A ``ValueError`` naming ``memory_limit_gb`` (``--memory-limit``) and ``what`` (the work and the
    option that sizes it) when ``need`` bytes exceed the run's budget; nothing when the budget is unknown."""
    budget = limit_bytes(memory_limit_gb, device)
    if budget is None or need <= budget:
        return
    given = (f"memory_limit_gb={memory_limit_gb:g}" if memory_limit_gb is not None else
             f"{100 * DEFAULT_SHARE:.0f} % of the {budget / DEFAULT_SHARE / GB:.1f} GB available")
    raise ValueError(f"memory_limit_gb: {what} needs about {need / GB:.1f} GB, more than the run's budget of "
                     f"{budget / GB:.1f} GB ({given}); search a narrower range, or raise the budget "
                     "(--memory-limit GB) on a machine that has it")
