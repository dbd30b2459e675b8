"""A video as ``tpnet process`` reads it: one folder per camera, each holding that camera's frames
(docs/outputs.md §5).

Frame ``i`` is the ``i``-th file of every folder in name order (``left/0001.png`` with ``right/0001.png``), read
as ``load_inputs`` reads one frame's files (ordinary images or raw files, with the rig given or the pair's
default). The folders must hold the same number of frame files (files of other kinds - a ``.txt``, a hidden
file - are not frames and are skipped); a folder with none, or counts that differ, is refused before any frame
is read. Frames are read one at a time, as they are processed: a file that cannot be read becomes that frame's
error (``Pipeline.stream`` reports it and goes on), not the end of the video.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from tpnet_gpu.io.stereo_io import IMAGE_SUFFIXES, TIFF_SUFFIXES

RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".pef", ".raf", ".raw")
FRAME_SUFFIXES = IMAGE_SUFFIXES + TIFF_SUFFIXES + RAW_SUFFIXES


def is_sequence(paths) -> bool:
    """True when ``paths`` are two or more folders none of which is a scene folder (a ``scene.json`` in it):
    one folder per camera of a video."""
    paths = [Path(p) for p in paths]
    return len(paths) >= 2 and all(p.is_dir() and not (p / "scene.json").exists() for p in paths)


def frames_in(folder: Path) -> list[Path]:
    """The frame files of ``folder`` in name order: entries with a ``FRAME_SUFFIXES`` suffix (case-insensitive),
    hidden ones and folders left out (a FIFO or a link is kept: reading it says what it is)."""
    return sorted(p for p in Path(folder).iterdir() if not p.name.startswith(".")
                  and p.suffix.lower() in FRAME_SUFFIXES and not p.is_dir())


def frame_files(folders) -> list[tuple[Path, ...]]:
    """``[(cam0_file, cam1_file, ...), ...]``: frame ``i`` is the ``i``-th frame file of each folder
    (``frames_in``).

    Raises:
        ValueError: a folder holds no frame file, or the folders hold different numbers of them (naming each
            folder's count).
    """
    folders = [Path(f) for f in folders]
    lists = []
    for folder in folders:
        files = frames_in(folder)
        if not files:
            raise ValueError(f"inputs: expected frame files ({', '.join(s for s in FRAME_SUFFIXES[:4])}, ...) in "
                             f"the camera folder {folder}, got none")
        lists.append(files)
    counts = [len(files) for files in lists]
    if len(set(counts)) > 1:
        said = ", ".join(f"{folder}: {n}" for folder, n in zip(folders, counts))
        raise ValueError(f"inputs: expected the same number of frames in every camera folder, got {said}")
    return list(zip(*lists))


def read_frames(files: list[tuple[Path, ...]], read) -> Iterator:
    """Frame after frame, ``read(paths)`` of each frame's files (e.g. ``load_inputs``); a frame whose read raises
    yields the exception instead (``Pipeline.stream`` makes it that frame's ``FrameError``)."""
    for paths in files:
        try:
            yield read(paths)
        except (OSError, ValueError) as exc:  # unreadable, corrupt, the wrong kind: this frame's error
            yield exc
