"""Issue 16's fuzz cases over ``Pipeline`` and their oracles, shared by the CI slice
(tests/fuzz/test_pipeline_fuzz.py) and the campaign (``tpnet bench fuzz``). Needs hypothesis (the ``test`` extra).

Two kinds of case:
* ``frames``: a pipeline for a drawn size, mono or Bayer, rig (quad, binocular, two_quads: tpnet_gpu/rigs, ideal
  at the frame size) and disparity range, given frames of a drawn dtype and magnitude (0, tiny, ordinary, 16-bit,
  huge), textured or featureless, with NaN/inf pixels sprinkled in. Oracles: nothing raises; every output has the
  shape ``FrameResult`` documents; where the disparity is finite (measured) the confidence is finite and >= 0,
  where it is NaN the confidence is 0; ``search`` is finite everywhere; ``valid`` and ``two_depth`` are bool.
* ``arguments``: one drawn bad constructor argument (size, cfa, range, device, pairs, rig, weights, config).
  Oracle: a ``ValueError``/``TypeError``/``FileNotFoundError`` whose message begins with that argument's name.
"""

from dataclasses import replace

import numpy as np
import torch
from hypothesis import strategies as st

from tpnet_gpu.io import rigfile
from tpnet_gpu.pipeline import Pipeline, PipelineConfig

SIZES = [(32, 48), (48, 64)]
RIGS = ("quad", "binocular", "two_quads")
RANGES = [(None, None), (0.0, 4.0), (-2.0, 6.0), (1.0, 1.5)]
MAGNITUDES = [0.0, 1e-30, 1.0, 4095.0, 65535.0, 1e11, 1e19]
DTYPES = [np.float32, np.float64, np.uint16, np.int32]
CONFIG = PipelineConfig()
# argument -> a bad value; the message must begin with the first name (several name the same argument)
BAD_ARGUMENTS = [
    ("height", dict(height=30)), ("width", dict(width=0)), ("cfa", dict(cfa="XYZ")), ("cfa", dict(cfa=3)),
    ("max_disparity", dict(max_disparity=float("nan"))),
    ("max_disparity", dict(min_disparity=3.0, max_disparity=1.0)),
    ("device", dict(device="gpu")), ("device", dict(device=0)), ("pairs", dict(pairs=[(0.5, 1)])),
    ("pairs", dict(pairs=[(0, 9)])), ("rig", dict(rig="quad")), ("weights", dict(weights="/nonexistent/w.pt")),
    ("camera_offsets", dict(rig="bad offsets")),
]

_pipelines = {}


def rig(name: str, height: int, width: int):
    """The shipped rig ``name`` made ideal at this frame size (as tests/test_pipeline_rigs.py does)."""
    return replace(rigfile.load(name), width=width, height=height, _cache={})


def pipeline(height, width, cfa, rig_name, d_range, backend="warp") -> Pipeline:
    """One pipeline per drawn combination, built once (a pipeline is reused for many frames, as a camera would)."""
    key = (height, width, cfa, rig_name, d_range, backend)
    if key not in _pipelines:
        _pipelines[key] = Pipeline(height, width, cfa=cfa, rig=rig(rig_name, height, width), device="cpu",
                                   min_disparity=d_range[0], max_disparity=d_range[1], backend=backend)
    return _pipelines[key]


@st.composite
def frame_cases(draw, sizes=SIZES):
    """A ``frames`` case (module docstring)."""
    height, width = draw(st.sampled_from(sizes))
    cfa = draw(st.sampled_from([None, "GRBG"]))
    rig_name = draw(st.sampled_from(RIGS))
    cams = rig(rig_name, height, width).cams
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    magnitude = draw(st.sampled_from(MAGNITUDES))
    textured = draw(st.booleans())
    base = rng.uniform(0, 1, (cams, height, width)) if textured else np.full((cams, height, width), 0.5)
    frames = base * magnitude
    dtype = draw(st.sampled_from(DTYPES))
    if np.issubdtype(dtype, np.integer):
        frames = np.clip(np.round(frames), 0, np.iinfo(dtype).max)
    frames = frames.astype(dtype)
    if dtype in (np.float32, np.float64):
        for _ in range(draw(st.integers(0, 3))):
            frames[rng.integers(cams), rng.integers(height), rng.integers(width)] = draw(
                st.sampled_from([np.nan, np.inf, -np.inf]))
    return dict(kind="frames", height=height, width=width, cfa=cfa, rig=rig_name, range=draw(st.sampled_from(RANGES)),
                frames=frames, magnitude=magnitude, textured=textured)


@st.composite
def argument_cases(draw):
    """An ``arguments`` case: the quad at 32x48 with one bad argument (module docstring)."""
    name, bad = draw(st.sampled_from(BAD_ARGUMENTS))
    return dict(kind="arguments", name=name, bad=bad)


def cases(sizes=SIZES):
    return st.one_of(frame_cases(sizes), argument_cases())


def _check_arguments(case) -> list:
    args = {**dict(height=32, width=48, device="cpu", backend="warp"), **case["bad"]}
    if args.get("rig") == "bad offsets":  # two cameras at one place
        args["rig"] = replace(rig("quad", 32, 48), offsets=((0.0, 0.0), (0.5, 0.0), (0.0, 0.0), (1.0, 1.0)))
    try:
        Pipeline(args.pop("height"), args.pop("width"), **args)
    except (ValueError, TypeError, FileNotFoundError) as exc:
        text = str(exc)
        named = text.startswith(case["name"]) or text.startswith(f"{case['bad'].get('weights', '')}:")
        return [] if named else [f"arguments: {case['name']}: message not naming it ({type(exc).__name__})"]
    except Exception as exc:  # noqa: BLE001 - any other exception is a failure to name the argument
        return [f"arguments: {case['name']}: raised {type(exc).__name__}"]
    return [f"arguments: {case['name']}: accepted"]


def _check_frames(case) -> tuple[list, int, int]:
    pipe = pipeline(case["height"], case["width"], case["cfa"], case["rig"], case["range"])
    try:
        result = pipe.process(case["frames"])
    except Exception as exc:  # noqa: BLE001 - every drawn frame is of a documented form: any raise fails
        return [f"frames: raised {type(exc).__name__}"], 0, 0
    grid = (case["height"] // 8, case["width"] // 8)
    failures = []
    for name in ("disparity", "confidence", "two_depth", "initial", "valid", "search"):
        if tuple(getattr(result, name).shape) != grid:
            failures.append(f"frames: {name} shape")
    channels = (2 if case["cfa"] is None else 4, case["height"], case["width"])
    if result.texture is None or tuple(result.texture.shape) != channels:
        failures.append("frames: texture shape")
    if failures:
        return failures, 0, 0
    d, conf = result.disparity.cpu().numpy(), result.confidence.cpu().numpy()
    measured = np.isfinite(d)
    if not (np.isfinite(conf[measured]).all() and (conf[measured] >= 0).all()):
        failures.append("frames: confidence not finite >= 0 where measured")
    if not (conf[~measured] == 0).all():
        failures.append("frames: confidence not 0 where unmeasured")
    if not np.isfinite(result.search.cpu().numpy()).all():
        failures.append("frames: search not finite")
    if result.valid.dtype != torch.bool or result.two_depth.dtype != torch.bool:
        failures.append("frames: masks not bool")
    return failures, int(np.prod(grid)), int(measured.sum())


def check(case) -> dict:
    """Run ``case`` against its oracles; ``tiles`` (tile tasks of the frame), ``valid`` (measured tiles) and
    ``failures`` (names of the oracles that failed)."""
    if case["kind"] == "arguments":
        return {"tiles": 0, "valid": 0, "failures": _check_arguments(case)}
    failures, tiles, measured = _check_frames(case)
    return {"tiles": tiles, "valid": measured, "failures": failures}
