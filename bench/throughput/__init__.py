"""Speed benches: the tile processor per stage (``bench_tp``, ``bench_throughput``: Warp, Taichi, the twins), the
whole pipeline per frame (``throughput_pipeline``), a stream soak (``throughput_stream``), start-up
(``bench_startup``), Ray (``bench_ray``); ``frame_memory`` and ``texture_kernels`` run on their own
(``python -m``)."""
