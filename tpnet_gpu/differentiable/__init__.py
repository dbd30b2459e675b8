"""A differentiable tile processor: the reference's math (``tpnet_gpu.reference``) in torch autograd, with
respect to pixel values and tile centres (hence, through a rig's Jacobian, its parameters). Device-agnostic:
any torch device and floating dtype (float64 for gradcheck, float32 for speed)."""

from tpnet_gpu.differentiable.tile import bayer_planes, convert_tiles, correlate, correlate_fd, corr_to_pixels

__all__ = ["bayer_planes", "convert_tiles", "correlate", "correlate_fd", "corr_to_pixels"]
