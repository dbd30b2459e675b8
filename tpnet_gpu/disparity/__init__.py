"""The disparity engine for any rig: pair geometry and axis sampling (``pairs``), cost volume and SGM
aggregation (``volume``), per-tile measurement (``measure``), the coarse-to-fine search and sparse refinement
(``engine``)."""

from tpnet_gpu.disparity.engine import DisparityEngine
from tpnet_gpu.disparity.results import DisparityResult

__all__ = ["DisparityEngine", "DisparityResult"]
