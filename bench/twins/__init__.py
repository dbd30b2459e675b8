"""The benchmark twins of the tile processor and its peers (``peers``: OpenCV SGBM, phaseCorrelate, scikit-image,
what a user would otherwise pick to measure disparity). The twins: the convert and correlate stages as vectorised float32 NumPy
(``numpy_tp``) and as plain PyTorch tensor ops (``torch_tp``), the peers the Warp kernels are timed against.
Their host-built operators come from ``tpnet_gpu.operators`` and their sizes from ``tpnet_gpu.layout``; the math
only they need (the closed-form basis expansion, the conjugate-product signs, the correlation weights) is in
``twins/common.py``. Neither imports the float64 reference, which is their oracle in the tests."""
