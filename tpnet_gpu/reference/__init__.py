"""Golden float64 NumPy reference of the tile-processor math (tile_processor.md §2-§7).

Readable, one function per step; it is the oracle the fast kernels are tested against and is never imported
by the fast path.
"""

from tpnet_gpu.reference.correlation import corr_to_pixels, correlate, correlate_fd, crop_centre, network_layers
from tpnet_gpu.reference.mclt import (
    bayer_planes,
    convert_tiles,
    dtt4_2d,
    extract_windows,
    fold,
    imclt,
    mclt,
    mclt_prerotation,
    overlap_add,
    pair_clamp,
    rotate,
    shifted_window,
    split_centre,
    tile_centres,
)
from tpnet_gpu.reference.products import bconj, bmul, correlation_product
from tpnet_gpu.tables import kernel_to_clt  # a table construction shared with the fast path
from tpnet_gpu.reference.transforms import dct2e, dct4, dst2e, dst4, dtt4

__all__ = [
    "bayer_planes", "bconj", "bmul", "convert_tiles", "corr_to_pixels", "correlate", "correlate_fd",
    "correlation_product", "crop_centre", "dct2e", "dct4", "dst2e", "dst4", "dtt4", "dtt4_2d",
    "extract_windows", "fold", "imclt", "kernel_to_clt", "mclt", "network_layers", "mclt_prerotation", "overlap_add",
    "pair_clamp", "rotate", "shifted_window", "split_centre", "tile_centres",
]
