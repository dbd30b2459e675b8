"""Pure input validators of the tile processor: each checks one argument at the public boundary and raises a
``ValueError``/``TypeError`` that names the argument, what was expected and what came. No device work."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tpnet_gpu import tables
from tpnet_gpu.config import BACKENDS
from tpnet_gpu.layout import DTT_SIZE, TILE_SIZE, TILE_STRIDE



@dataclass(frozen=True)
class Geometry:
    """What a processor is built for: frame size, cameras, pairs and colours (validated)."""

    height: int
    width: int
    offsets: np.ndarray  # (cams, 2) float32, baselines (x right, y down)
    pairs: tuple[tuple[int, int], ...]
    cfa: str | None

    @property
    def tiles_y(self) -> int:
        return self.height // TILE_STRIDE

    @property
    def tiles_x(self) -> int:
        return self.width // TILE_STRIDE

    @property
    def tiles(self) -> int:
        return self.tiles_y * self.tiles_x

    @property
    def cams(self) -> int:
        return self.offsets.shape[0]

    @property
    def colours(self) -> int:
        return 1 if self.cfa is None else 3


def frame_size(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < TILE_SIZE or value % DTT_SIZE:
        raise ValueError(f"{name}: expected a multiple of {DTT_SIZE} that is at least {TILE_SIZE}, got {value!r}")
    return int(value)


def camera_offsets(offsets) -> np.ndarray:
    """``(cams >= 2, 2)`` finite offsets (two cameras may share a place: e.g. one camera correlated with itself
    through other kernels, or at two times; a texture refuses that, ``distinct_offsets``)."""
    try:
        out = np.asarray(offsets, dtype=np.float32)
    except (TypeError, ValueError) as exc:  # ragged lists, strings: NumPy's message would not name the argument
        raise ValueError(f"camera_offsets: expected shape (cams >= 2, 2) of numbers, got {offsets!r} ({exc})") from None
    if out.ndim != 2 or out.shape[1] != 2 or out.shape[0] < 2:
        raise ValueError(f"camera_offsets: expected shape (cams >= 2, 2), got {out.shape}")
    if not np.isfinite(out).all():
        raise ValueError(f"camera_offsets: expected finite numbers, got {out.tolist()}")
    return out


def distinct_offsets(offsets: np.ndarray) -> None:
    """A texture's cameras ``(cams, 2)`` at distinct places: the texture's weights of two cameras that always
    agree were 0/0, an all-NaN texture (issue 16)."""
    for i in range(len(offsets)):
        same = np.flatnonzero(np.all(offsets[i + 1:] == offsets[i], axis=1))
        if same.size:
            raise ValueError(f"camera_offsets: expected a distinct place per camera for textures=True, got cameras "
                             f"{i} and {i + 1 + same[0]} both at {offsets[i].tolist()}")


def _index(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def pairs(value, cams: int) -> tuple[tuple[int, int], ...]:
    """Camera pairs: a non-empty sequence of (first, second) integer indices (floats are refused, not rounded)."""
    expected = f"a sequence of (first, second) pairs of distinct integer camera indices in 0..{cams - 1}"
    try:
        items = list(value)
    except TypeError:
        raise ValueError(f"pairs: expected {expected}, got {value!r}") from None
    if not items:
        raise ValueError("pairs: expected at least one (first, second) camera pair, got none")
    out = []
    for item in items:
        pair = tuple(item) if isinstance(item, (tuple, list, np.ndarray)) else (item,)
        if len(pair) != 2 or not all(_index(v) for v in pair) or pair[0] == pair[1] \
                or not all(0 <= v < cams for v in pair):
            raise ValueError(f"pairs: expected {expected}, got {item!r}")
        out.append((int(pair[0]), int(pair[1])))
    return tuple(out)


def device(value) -> str:
    """A Warp device name from ``value``: None (cuda when present, else cpu), "cpu", "cuda", "cuda:N" or a
    ``torch.device`` of those ("cpu:0" is the cpu); anything else, or CUDA where none is present, is refused."""
    import warp as wp  # noqa: PLC0415 - initialised by the caller

    from tpnet_gpu.runtime.warp_setup import default_device  # noqa: PLC0415

    if value is None:
        return default_device()
    text = str(value) if isinstance(value, (str, torch.device)) else None
    if text in ("cpu", "cpu:0"):
        return "cpu"
    if text is None or not (text == "cuda" or (text.startswith("cuda:") and text[5:].isdigit())):
        raise ValueError(f"device: expected 'cpu', 'cuda', 'cuda:N' or such a torch.device, got {value!r}")
    if not wp.is_cuda_available():
        raise ValueError(f"device: {text!r} asked for, but no CUDA device is present (use 'cpu')")
    if text != "cuda" and int(text[5:]) >= wp.get_cuda_device_count():
        raise ValueError(f"device: expected cuda:0..cuda:{wp.get_cuda_device_count() - 1}, got {text!r}")
    return text


def geometry(height, width, offsets, pair_list, cfa) -> Geometry:
    """All of the processor's shape arguments, checked."""
    height, width = frame_size("height", height), frame_size("width", width)
    offsets = camera_offsets(offsets)
    if cfa is not None:
        tables.cfa_red_position(cfa)  # names the allowed patterns
    return Geometry(height, width, offsets, pairs(pair_list, offsets.shape[0]), cfa)


def backend(name, graph) -> None:
    if name is not None and name not in BACKENDS:
        raise ValueError(f"backend: expected one of {BACKENDS} or None, got {name!r}")
    if name == "taichi" and graph:
        raise ValueError("graph: graph capture records Warp launches; it needs backend='warp', got backend='taichi'")


def kernels(value, geo: Geometry) -> np.ndarray | None:
    """Aberration kernels ``(cams, rows, cols, colours, 4, 8, 8)`` float32 (a 5-D per-camera set gets a 1x1 grid),
    or None."""
    if value is None:
        return None
    k = value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else np.asarray(value)
    if not (np.issubdtype(k.dtype, np.floating) or np.issubdtype(k.dtype, np.integer)):
        raise TypeError(f"kernels: expected real values (float or integer), got {k.dtype}")
    expected = f"(cams={geo.cams}, [rows >= 1, cols >= 1,] colours={geo.colours}, 4, 8, 8)"
    if k.ndim == 5:
        k = k[:, None, None]
    # an empty kernel grid would leave the kernels' lookup nothing to read (issue 16: a crash in process)
    if (k.ndim != 7 or k.shape[0] != geo.cams or min(k.shape[1:3]) < 1
            or k.shape[3:] != (geo.colours, 4, DTT_SIZE, DTT_SIZE)):
        raise ValueError(f"kernels: expected shape {expected}, got {tuple(k.shape)}")
    if not np.all(np.isfinite(k)):
        raise ValueError("kernels: expected finite values, got NaN or infinity")
    return np.ascontiguousarray(k, dtype=np.float32)


def _numpy(name: str, value: np.ndarray) -> np.ndarray:
    """``value`` in a form torch can wrap: masked values as NaN (a masked array's mask is honoured, issue 16),
    native byte order and non-negative strides (copies only for those)."""
    if value.dtype.kind not in "biufc":  # torch.from_numpy's own message would not name the argument
        raise TypeError(f"{name}: expected numbers, got a numpy array of {value.dtype}")
    if isinstance(value, np.ma.MaskedArray):
        floating = value.dtype if value.dtype.kind in "fc" else np.float32
        value = np.ma.filled(value.astype(floating), np.nan)
    if not value.dtype.isnative:
        value = value.astype(value.dtype.newbyteorder("="))
    if any(stride < 0 for stride in value.strides):
        value = np.ascontiguousarray(value)
    return value


def _tensor(name: str, value, shape: tuple, axes: str, kinds: str) -> torch.Tensor:
    """``value`` as a dense torch tensor with data, of ``shape`` (NumPy arrays are wrapped, copied only when
    ``_numpy`` must)."""
    if isinstance(value, np.ndarray):
        value = torch.from_numpy(_numpy(name, value))
    if not isinstance(value, torch.Tensor):
        raise TypeError(f"{name}: expected {kinds}, got {type(value).__name__}")
    if value.layout != torch.strided:
        raise TypeError(f"{name}: expected a dense tensor, got layout {value.layout} (call .to_dense())")
    if value.is_meta:
        raise TypeError(f"{name}: expected a tensor with data, got one on the meta device")
    if tuple(value.shape) != shape:
        raise ValueError(f"{name}: expected shape {shape} ({axes}), got {tuple(value.shape)}")
    return value


def frames(value, geo: Geometry) -> torch.Tensor:
    """``(cams, height, width)`` real-valued frames as a torch tensor."""
    value = _tensor("frames", value, (geo.cams, geo.height, geo.width), "cams, height, width",
                    "a torch tensor or numpy array")
    if value.dtype.is_complex or value.dtype == torch.bool:
        raise TypeError(f"frames: expected real pixel values (float or integer), got {value.dtype}")
    return value


def _floating(name: str, value, shape: tuple, axes: str) -> torch.Tensor:
    value = _tensor(name, value, shape, axes, "a number, torch tensor or numpy array")
    if not value.dtype.is_floating_point:
        raise TypeError(f"{name}: expected a floating-point dtype, got {value.dtype}")
    return value


def target_disparity(value, geo: Geometry) -> float | torch.Tensor:
    """A number or a ``(tiles_y, tiles_x)`` floating-point tensor of target disparities."""
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        return float(value)
    return _floating("target_disparity", value, (geo.tiles_y, geo.tiles_x), "tiles_y, tiles_x")


def centres(value, geo: Geometry) -> torch.Tensor:
    """``(tiles, cams, 2)`` floating-point per-camera tile centres."""
    if isinstance(value, (int, float)):
        raise TypeError(f"centres: expected a torch tensor or numpy array, got {type(value).__name__}")
    return _floating("centres", value, (geo.tiles, geo.cams, 2), "tiles, cams, x/y")


def active(value, geo: Geometry) -> torch.Tensor | None:
    """None (every tile) or a bool mask of shape ``(tiles_y, tiles_x)`` or ``(tiles,)``, returned flat. Any
    other shape of the same size (a transposed grid) is refused: it would select the wrong tiles."""
    if value is None:
        return None
    if isinstance(value, np.ndarray):
        value = torch.from_numpy(value)
    shapes = ((geo.tiles_y, geo.tiles_x), (geo.tiles,))
    if not isinstance(value, torch.Tensor) or value.dtype != torch.bool or tuple(value.shape) not in shapes:
        got = f"{value.dtype} of shape {tuple(value.shape)}" if isinstance(value, torch.Tensor) else type(value)
        raise ValueError(f"active: expected a bool mask of shape {shapes[0]} (tiles_y, tiles_x) or {shapes[1]}, "
                         f"got {got}")
    return value.reshape(-1)


def targets(disparity, centre_list) -> None:
    if (disparity is None) == (centre_list is None):
        raise ValueError("process: give exactly one of target_disparity and centres")
