"""Benchmarks, run as ``tpnet bench NAME`` (``tpnet_gpu.cli.bench``: a table printed, JSON saved) or ``python -m
tpnet_gpu.bench.GROUP.MODULE``: ``accuracy/`` (rendered and real pairs against ground truth), ``throughput/``
(speed, memory, start-up, Ray), ``twins/`` (the tile processor in NumPy and torch, and the peers a user would
otherwise pick, OpenCV SGBM), ``fuzz/`` (the hostile-input campaign); ``common.py`` is shared by all."""
