"""Accuracy benches: rendered scenes with exact ground truth (``bench_accuracy``, ``bench_network``,
``bench_network_limits``, ``bench_network_context``, ``bench_two_surface``, ``bench_flow``,
``bench_calibration``), rendered pairs that fail the way photographs do (``bench_rendered_pairs``) and real pairs
(``bench_real``); ``report``, ``real_pairs`` and ``rendered_pairs`` hold their shared scoring."""
