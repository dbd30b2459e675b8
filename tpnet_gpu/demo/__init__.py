"""``tpnet demo``: the built-in rendered scene through the pipeline (``run``) and its report and figures
(``report``)."""

from tpnet_gpu.demo.run import run_demo

__all__ = ["run_demo"]
