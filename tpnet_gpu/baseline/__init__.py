"""Hand-crafted disparity baseline (geometry_and_lma.md B, C)."""
