"""Sizes of the tile processor's data layout, one home for each (tile_processor.md §1, §6.3; network.md §1).

Pure Python, no Warp or Taichi import: the Warp kernels, the Taichi kernels, the float64 reference, the host
tables and the benchmark twins all read these names, so none of them retypes a size.
"""

DTT_SIZE = 8  # N: points of one 8-point transform; frequencies per axis
TILE_SIZE = 2 * DTT_SIZE  # 16: side of a tile's window, pixels
HALF_TILE = DTT_SIZE  # 8: window corner = tile centre - HALF_TILE
TILE_STRIDE = DTT_SIZE  # 8: tile grid step, pixels; tile (tx, ty) is centred at (8 tx + 4, 8 ty + 4)
TILE_CENTRE = TILE_STRIDE / 2  # 4.0: the centre of tile 0, pixels (camera.grid_centres)
CORR_RADIUS = 7  # pixel-domain correlations keep lags -7..7 (lag +-8 is dropped)
CORR_SIDE = 2 * CORR_RADIUS + 1  # 15
NET_RADIUS = 4  # the network reads the 9x9 centre of each combined correlation
NET_SIDE = 2 * NET_RADIUS + 1  # 9
NET_CROP = CORR_RADIUS - NET_RADIUS  # 3: first row/column of the network's crop inside a 15x15 correlation
NET_LAYERS = 4  # combined layers per tile: hor, vert, diag-main, diag-other

# Margin of the padded frames. Even, so padding keeps the Bayer parity; >= TILE_SIZE + 1, so that *any* integer
# window corner can be moved onto the padded frame without changing what the pair-preserving clamp reads.
PAD = 18
# Centres further than this from the image (pixels) are clamped before rounding (int32 safety only).
CENTRE_LIMIT = 1.0e6
# Pixels of larger magnitude count as not finite (their tile invalid, its windows zero-filled): a window's CLT
# reaches ~64 x its largest pixel, a pair product ~4 x the square of that: 2^50 keeps every product below float32's
# 3.4e38 with a margin of ~1e4 for aberration-kernel gains (issue 16: >= 1e19 gave NaN correlations).
PIXEL_LIMIT = 2.0**50
# Largest finite float32: a number of larger magnitude is NaN or infinite.
FLOAT32_MAX = 3.4028234e38

# Threads per block of the tile kernels on CUDA, and of every per-thread launch there (one block size per module
# keeps Warp from compiling a module twice). On the CPU a block is one lane (platform.md §1).
CUDA_BLOCK_DIM = 64
CPU_BLOCK_DIM = 1
# Workers of the fused tile pass, each with its own scratch of one tile's spectra (cams x used colours x 4 x 8 x 8):
# on CUDA one block / thread each (tiles beyond are taken in turn; 8192 x 4 cams x 3 colours: ~100 MB); on the
# CPU many per Taichi thread: Taichi hands a CPU thread whole chunks of a loop's iterations (16 slots ran on one
# thread, measured), and 512 per thread keep both threads busy (quad, 3 colours: 12 MB for 2 threads).
CUDA_FUSED_SLOTS = 8192
CPU_FUSED_SLOTS_PER_THREAD = 512
