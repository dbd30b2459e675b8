"""``tpnet process CAM0_DIR CAM1_DIR ...``: a video, one folder of frames per camera (``tpnet_gpu.io.sequence``).

Each frame starts from the one before's answers (``Pipeline.stream(follow=True)``: the engine re-searches only the
tiles whose answer no longer holds, with a full search on the first frame, every 8th, after a bad one and on a
cut); ``--no-follow`` searches every frame. Output (docs/outputs.md §5): ``OUT/frame_NNNNN/`` with one frame's
files each, and ``OUT/sequence.json`` (per frame: its files, seconds, tile passes, whether it followed the frame
before and the rig's forward motion it measured, or the error that frame gave). A frame that cannot be read or
processed is reported on stderr and in the JSON, the others are written; the exit status is then 1. The folder is
put in place whole when the video ends (``outputs.output_folder``).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path


def frame_folder(index: int) -> str:
    """The sub-folder of frame ``index``: ``frame_00000``, ..."""
    return f"frame_{index:05d}"


def process_sequence(args: argparse.Namespace, step, out: Path, min_d: float | None, max_d: float | None) -> int:
    """Run ``tpnet process`` on the camera folders ``args.inputs`` (module docstring); ``out`` is claimed."""
    from tpnet_gpu.cli.common import pipeline_for  # noqa: PLC0415
    from tpnet_gpu.io import rigfile, sequence  # noqa: PLC0415
    from tpnet_gpu.io.stereo_io import load_inputs  # noqa: PLC0415 - torch and Warp on use
    from tpnet_gpu.outputs import frame_outputs, output_folder  # noqa: PLC0415
    from tpnet_gpu.pipeline import FrameError  # noqa: PLC0415

    step("reading the inputs")
    files = sequence.frame_files(args.inputs)
    rig = rigfile.load(args.rig) if args.rig is not None else None  # read once, not per frame

    def read(paths):
        return load_inputs(list(paths), rig=rig, cfa=args.cfa, colour=args.colour, reference=args.reference)

    items = sequence.read_frames(files, read)
    leading = []  # the frames read to build the pipeline (failures, then the first that reads): not read again
    for item in items:
        leading.append(item)
        if not isinstance(item, Exception):
            break
    first = leading[-1]
    if isinstance(first, Exception):  # no frame reads: say why the first one did not
        raise leading[0]
    step("pipeline set-up")
    pipeline = pipeline_for(args, first, min_d, max_d, args.backend)
    what = frame_outputs.method(pipeline)
    read_inputs = []  # each frame's Inputs (cropping, white level), consumed in step with the stream

    def frames():
        for item in itertools.chain(leading, items):
            read_inputs.append(item)
            yield item if isinstance(item, Exception) else item.frames.frames

    step("frames")
    records, failed = [], 0
    with output_folder(out, overwrite=args.overwrite, inputs=args.inputs) as folder:
        start = time.perf_counter()
        for result in pipeline.stream(frames(), follow=not args.no_follow):
            index = len(records)
            inputs = read_inputs[index]
            record = {"frame": index, "files": [str(p) for p in files[index]],
                      "seconds": round(time.perf_counter() - start, 4)}
            if isinstance(result, FrameError):
                failed += 1
                record["error"] = f"{type(result.error).__name__}: {result.error}"
                print(f"frame {index} ({', '.join(p.name for p in files[index])}): {result.error}", file=sys.stderr)
            else:
                maps = frame_outputs.from_result(result, inputs.rig, frames=inputs.frames,
                                                 white=inputs.frames.white_level if inputs.kind in ("pair", "images")
                                                 else None)
                sub = folder / frame_folder(index)
                sub.mkdir()
                frame_outputs.write(sub, maps, scene=f"frame {index}", what=what, figures=not args.no_figures,
                                    per_pixel=args.per_pixel)
                if args.two_surface:  # NaN where the tile shows one surface, as for one frame
                    frame_outputs.write_surfaces(sub, result.surfaces, inputs.frames)
                record.update(folder=sub.name, tile_passes=round(float(result.tile_passes), 3),
                              followed=result.engine.followed, forward_motion=result.engine.motion)
            records.append(record)
            start = time.perf_counter()
        summary = {"frames": len(records), "failed": failed, "follow": not args.no_follow, "method": what,
                   "inputs": [str(p) for p in args.inputs], "per_frame": records}
        (folder / "sequence.json").write_text(json.dumps(summary, indent=1))
    step.close()
    done = [r for r in records if "error" not in r]
    seconds = sorted(r["seconds"] for r in done)
    passes = [r["tile_passes"] for r in done]
    h, w = first.frames.size
    print(f"processed {len(done)} of {len(records)} frames ({w}x{h}, {first.frames.cams} cameras) -> {out}: "
          + (f"median {seconds[len(seconds) // 2]:.2f} s and {sum(passes) / len(passes):.2f} tile passes per frame "
             if done else "") + f"({'following' if not args.no_follow else 'searching'} each frame; {what})"
          + (f"; {failed} failed (sequence.json)" if failed else ""))
    return 1 if failed else 0
