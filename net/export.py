"""TPNET to ONNX (issue 18): the whole-frame form (stage 1 + stage 2, network.md §3, §12) as one graph whose frame
size, in tiles, is dynamic, for onnxruntime, TensorRT and the like.

The graph is :class:`FrameNetwork`: ``layers (tiles_y, tiles_x, G, 9, 9)`` float32 and ``target
(tiles_y, tiles_x)`` float32 in, ``disparity (tiles_y, tiles_x)`` = target + residual (clone 0, the 5x5 stage 2,
as the pipeline runs it; NaN targets stay NaN) out: what ``tpnet_gpu.net.infer.infer`` returns, from the same
functional core (net/model.py), so there is one copy of the math. It is traced with torch's dynamo exporter
(``torch.onnx.export(..., dynamo=True)``, which needs the ``onnx`` extra: onnx, onnxscript; onnxruntime to
run the result). The file is written whole or not at all (``tpnet_gpu.outputs.output_file``).
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from pathlib import Path

import torch
from torch import Tensor, nn

from tpnet_gpu.net.frame import frame_residual
from tpnet_gpu.net.functional import CORR_SIZE
from tpnet_gpu.net.model import TPNet

OPSET = 18  # the opset the exporter was checked with (onnxruntime 1.2x runs it)
INPUTS = ("layers", "target")
OUTPUTS = ("disparity",)
EXAMPLE_GRID = (6, 8)  # tiles of the example frame the graph is traced on (any size >= 2x2 runs after)


class FrameNetwork(nn.Module):
    """A ``TPNet``'s whole-frame prediction as a module of two tensors, for export.

    Args:
        model: the network (its parameters are shared, not copied).

    Shape:
        - layers: :math:`(ty, tx, G, 9, 9)` correlation layers (G = ``model.layers``, the quad's 4).
        - target: :math:`(ty, tx)` target disparities, px (NaN: no target).
        - output: :math:`(ty, tx)` predicted disparity = target + residual of clone 0.

    >>> FrameNetwork(TPNet())(torch.zeros(3, 4, 4, 9, 9), torch.zeros(3, 4)).shape
    torch.Size([3, 4])
    """

    def __init__(self, model: TPNet) -> None:
        super().__init__()
        if not isinstance(model, TPNet):
            raise TypeError(f"model: expected a TPNet, got {type(model).__name__}")
        self.model = model

    def forward(self, layers: Tensor, target: Tensor) -> Tensor:
        stage1, stage2 = self.model._params()
        return target + frame_residual(layers, target, stage1, stage2, clone=0, steps=False)  # symbolic tile counts


def _onnx_modules() -> int:
    """Import the exporter's dependencies or say which extra brings them; the highest opset the installed onnx
    knows (the version converter's limit)."""
    try:
        import onnx  # noqa: PLC0415 - the dynamo exporter writes through them
        import onnxscript  # noqa: F401, PLC0415
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(f"ONNX export needs the '{exc.name}' package: pip install 'tpnet-gpu[onnx]'",
                                  name=exc.name) from exc
    return int(onnx.defs.onnx_opset_version())


@contextlib.contextmanager
def _quiet_exporter():
    """The exporter's warnings and log lines (torchvision ops it skips, axis names it merges) off the user's
    terminal: they are about torch's internals, not the file written."""
    loggers = [logging.getLogger(name) for name in ("torch.onnx", "torch.export", "onnxscript")]
    levels = [lg.level for lg in loggers]
    try:
        for lg in loggers:
            lg.setLevel(logging.ERROR)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


def export_onnx(model: TPNet, path, *, overwrite: bool = False, opset: int = OPSET) -> Path:
    """Write ``model``'s whole-frame form (:class:`FrameNetwork`) to the ONNX file ``path``, tiles dynamic.

    Args:
        model: the network (e.g. ``tpnet_gpu.net.infer.load()``); exported on the CPU in float32, in eval mode.
        path: the ``.onnx`` file; written whole (a temporary file beside it, then renamed).
        overwrite: replace an existing file (default: refuse it).
        opset: ONNX opset (at least 18, the dynamo exporter's).

    Returns:
        ``path`` resolved. Inputs ``layers`` :math:`(tiles\\_y, tiles\\_x, G, 9, 9)`, ``target``
        :math:`(tiles\\_y, tiles\\_x)`; output ``disparity`` :math:`(tiles\\_y, tiles\\_x)`, all float32, with
        ``tiles_y``, ``tiles_x`` >= 2 dynamic.

    Raises:
        TypeError: ``model`` not a TPNet. ValueError: ``opset`` below 18; ``path`` not ending in .onnx, a
        folder, or an existing file without ``overwrite``. ModuleNotFoundError: onnx/onnxscript missing.
    """
    from tpnet_gpu.outputs import output_file  # noqa: PLC0415

    if isinstance(opset, bool) or not isinstance(opset, int) or opset < OPSET:
        raise ValueError(f"opset: expected an int >= {OPSET} (the dynamo exporter's), got {opset!r}")
    if Path(path).suffix != ".onnx":
        raise ValueError(f"path: expected a file name ending in .onnx, got {str(path)!r}")
    wrapper = FrameNetwork(model)  # checks the model before any work
    highest = _onnx_modules()
    if opset > highest:  # the exporter would fall back to 18 with a traceback and say nothing
        raise ValueError(f"opset: expected an int in {OPSET}..{highest} (the installed onnx knows no later one), "
                         f"got {opset}")
    net = wrapper.to("cpu", torch.float32).eval()
    g = model.layers
    example = (torch.zeros(*EXAMPLE_GRID, g, CORR_SIZE, CORR_SIZE), torch.zeros(EXAMPLE_GRID))
    ty, tx = torch.export.Dim("tiles_y", min=2), torch.export.Dim("tiles_x", min=2)
    with output_file(path, overwrite=overwrite, option="path") as tmp, torch.no_grad(), _quiet_exporter():
        program = torch.onnx.export(net, example, dynamo=True, opset_version=opset, input_names=list(INPUTS),
                                    output_names=list(OUTPUTS), dynamic_shapes={"layers": {0: ty, 1: tx},
                                                                                 "target": {0: ty, 1: tx}},
                                    optimize=True, verbose=False)
        written = {i.domain: i.version for i in program.model_proto.opset_import}
        if written.get("", written.get("ai.onnx")) != opset:  # nothing is put in place
            raise ValueError(f"opset: the exporter could not write opset {opset} (it made {written}); try {OPSET}")
        program.save(str(tmp), external_data=False)  # one self-contained file (the weights are ~1.4 MB)
    return Path(path).resolve()
