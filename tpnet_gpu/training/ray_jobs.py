"""Many scenes on many workers with Ray (issue 18; docs/scaling.md): scene folders through ``tpnet process`` and data
set chunks through ``tpnet_gpu.training.dataset.write_chunk``, spread over a pool of Ray actors by Ray Data's
``map_batches`` (one scene per call).

Each actor is one worker process that keeps what is costly to make - its pipelines or its data-set measurers, with
their device buffers, and the compiled kernels - for every scene it is given; one actor per CPU (one torch and one
Taichi thread each) or, where the cluster has GPUs, one per GPU. Ray starts locally (``ray.init(num_cpus=
workers)``) unless an address names a cluster. A scene writes exactly what the serial command writes (the same
code runs: ``tpnet process``'s own function, the data set's one chunk writer), whole or not at all, so a present
output means done: a second run skips it (resume). Ray is the optional ``ray`` extra, imported on use.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import logging
import os
import time
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

RAY_EXTRA = "pip install 'tpnet-gpu[ray]'"
# Every worker runs one thread of each library: the pool, not the thread count, spreads the work over the cores
# (2 workers x 2 Taichi threads on 2 cores ran slower than 2 x 1).
WORKER_ENV = {"TPNET_TAICHI_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
OBJECT_STORE_BYTES = 256 * 2**20  # local Ray: rows are file names, not frames; Ray's default takes 30% of RAM
PIPELINES_KEPT = 4  # pipelines an actor keeps (one per frame size, rig and options; least recently used dropped)


@dataclass(frozen=True)
class RayOptions:
    """Where and how wide to run: ``address`` of a Ray cluster (None: start Ray on this machine), ``workers``
    (actors; None: one per CPU here, or per GPU / CPU of the cluster)."""

    address: str | None = None
    workers: int | None = None

    def __post_init__(self):
        if self.workers is not None and (isinstance(self.workers, bool) or not isinstance(self.workers, int)
                                         or self.workers < 1):
            raise ValueError(f"--workers: expected a positive number of workers, got {self.workers!r}")


def import_ray():
    """``ray`` with Ray Data, or a ModuleNotFoundError that names the extra to install."""
    try:
        import ray  # noqa: PLC0415 - the optional extra
        import ray.data  # noqa: F401, PLC0415
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(f"--ray needs the '{exc.name}' package: {RAY_EXTRA}", name=exc.name) from exc
    return ray


@contextlib.contextmanager
def session(options: RayOptions) -> Iterator[tuple[int, bool]]:
    """Ray started (or joined) for one job and shut down after it; yields ``(workers, gpu)``: the pool size and
    whether each actor takes a GPU (the cluster has GPUs)."""
    ray = import_ray()
    started = not ray.is_initialized()
    if started:
        env = {"runtime_env": {"env_vars": WORKER_ENV}, "logging_level": "WARNING", "log_to_driver": False}
        if options.address is None:
            ray.init(num_cpus=options.workers or os.cpu_count(), include_dashboard=False,
                     object_store_memory=OBJECT_STORE_BYTES, **env)
        else:
            ray.init(address=options.address, **env)
    try:
        resources = ray.cluster_resources()
        gpus = int(resources.get("GPU", 0))
        yield options.workers or gpus or max(1, int(resources.get("CPU", 1))), gpus > 0
    finally:
        if started:
            ray.shutdown()


def run_pool(items: list[dict], worker: type, kwargs: dict, options: RayOptions, *, desc: str,
             progress: bool = True) -> list[dict]:
    """Every item (a row of plain values) through ``worker(**kwargs)(batch)`` on a Ray actor pool, one item per
    call; returns the rows the workers return, as they finish (a progress bar counts them)."""
    from tpnet_gpu.runtime.progress import bar as progress_bar  # noqa: PLC0415

    if not items:
        return []
    with session(options) as (workers, gpu):
        import ray.data  # noqa: PLC0415 - imported by session

        logging.getLogger("ray.data").setLevel(logging.ERROR)  # its plan and progress notes: ours counts scenes
        context = ray.data.DataContext.get_current()
        context.enable_progress_bars = False
        context.execution_options.preserve_order = False
        data = ray.data.from_items(items, override_num_blocks=len(items))  # one block per scene: all can start
        pool = ray.data.ActorPoolStrategy(size=min(workers, len(items)), max_tasks_in_flight_per_actor=1)
        data = data.map_batches(worker, fn_constructor_kwargs=kwargs, batch_size=1, compute=pool,
                                num_cpus=0 if gpu else 1, num_gpus=1 if gpu else 0)
        rows = []
        with progress_bar(total=len(items), desc=desc, unit="scene", progress=progress) as bar:
            for row in data.iter_rows():
                rows.append(row)
                bar.update()
        return rows


def one_thread() -> None:
    """A worker's torch on one thread (Taichi's count comes from ``WORKER_ENV`` before it starts)."""
    import torch  # noqa: PLC0415

    torch.set_num_threads(1)


# ------------------------------------------------------------------------------------------ tpnet process
class _Pipelines:
    """``stereo_io.make_pipeline`` that hands back the pipeline it made before for the same size, rig and options
    (a pipeline allocates its buffers once per frame size and can run any number of frames)."""

    def __init__(self, make):
        self.make, self.kept = make, OrderedDict()

    def __call__(self, inputs, **options):
        from tpnet_gpu.io.rigfile import rig_to_dict  # noqa: PLC0415

        key = (inputs.frames.padded, inputs.frames.cfa, inputs.kind, json.dumps(rig_to_dict(inputs.rig), sort_keys=True),
               json.dumps(options, sort_keys=True))
        if key not in self.kept:
            self.kept[key] = self.make(inputs, **options)
            if len(self.kept) > PIPELINES_KEPT:
                self.kept.popitem(last=False)
        self.kept.move_to_end(key)
        return self.kept[key]


@contextlib.contextmanager
def reused_pipelines() -> Iterator[None]:
    """While open, ``tpnet process`` (which makes its pipeline through ``stereo_io.make_pipeline`` on each call)
    reuses the pipelines of earlier calls in this process."""
    from tpnet_gpu.io import stereo_io  # noqa: PLC0415

    make = stereo_io.make_pipeline
    stereo_io.make_pipeline = _Pipelines(make)
    try:
        yield
    finally:
        stereo_io.make_pipeline = make


def process_scene(folder: str, out: str, options: dict) -> dict:
    """``tpnet process FOLDER --out OUT`` with the other options of the command (``options``: its parsed
    arguments, ``func`` the command's function) in this process; returns the row of :func:`run_pool`: the
    scene, its seconds, the command's own line, and the error of bad input ('' if none)."""
    args = argparse.Namespace(**{**options, "inputs": [folder], "out": out, "ray": False})
    start, printed = time.perf_counter(), io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            args.func(args)
        error = ""
    except (ValueError, OSError) as exc:  # what the command line reports as bad input (a TypeError is a bug)
        error = str(exc)
    return {"scene": Path(folder).name, "seconds": time.perf_counter() - start,
            "message": printed.getvalue().strip(), "error": error}


class SceneWorker:
    """A Ray actor: :func:`process_scene` for each scene it is given, its pipelines kept between scenes."""

    def __init__(self, options: dict):
        one_thread()
        self.options = options
        self._reuse = reused_pipelines()
        self._reuse.__enter__()  # for the actor's life: it is a process of its own

    def __call__(self, batch):
        rows = [process_scene(str(f), str(o), self.options) for f, o in zip(batch["folder"], batch["out"])]
        return {key: [row[key] for row in rows] for key in rows[0]}


# ------------------------------------------------------------------------------------------ tpnet dataset
class ChunkWorker:
    """A Ray actor: data-set chunks (``dataset.write_chunk``) with its own measurers (engine, processor,
    layers), made once."""

    def __init__(self, folder: str, spec: dict, device: str | None):
        from tpnet_gpu.training.dataset import DatasetSpec, measurers  # noqa: PLC0415

        one_thread()
        self.folder, self.spec = folder, DatasetSpec(**spec)
        self.measurers = measurers(self.spec, device)

    def __call__(self, batch):
        from tpnet_gpu.training.dataset import write_chunk  # noqa: PLC0415

        scenes, seconds = [], []
        for index in batch["index"]:
            start = time.perf_counter()
            write_chunk(self.folder, int(index), self.spec, *self.measurers)
            scenes.append(f"scene {int(index)}")
            seconds.append(time.perf_counter() - start)
        return {"scene": scenes, "seconds": seconds, "error": [""] * len(scenes)}


def chunk_builder(options: RayOptions):
    """``dataset.build``'s ``chunks``: the missing scenes written by ``build_chunks`` with these options."""
    return functools.partial(build_chunks, options=options)


def build_chunks(folder, spec, indices, options: RayOptions, *, device: str | None = None,
                 progress: bool = True) -> list[dict]:
    """Chunks of the scenes ``indices`` of the data set ``spec`` into ``folder`` on Ray workers."""
    from dataclasses import asdict  # noqa: PLC0415

    import_ray()
    items = [{"index": int(i)} for i in indices]
    kwargs = {"folder": str(Path(folder).resolve()), "spec": asdict(spec), "device": device}
    return run_pool(items, ChunkWorker, kwargs, options, desc="scenes", progress=progress)
