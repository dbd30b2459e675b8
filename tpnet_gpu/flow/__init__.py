"""Motion vectors: per-tile 2-D flow between frames of one camera (``estimator``), its coarse starts (``starts``)
and the alignment of a moving rig's frames (``align``); ``tpnet flow`` on the command line."""

from tpnet_gpu.flow.estimator import FlowConfig, FlowEstimator, FlowResult, estimate_flow

__all__ = ["FlowConfig", "FlowEstimator", "FlowResult", "estimate_flow"]
