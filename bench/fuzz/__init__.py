"""The hostile-input campaign (``tpnet bench fuzz``): tile-processor, pipeline, raw-file and command-line cases
with their oracles, each run in a child process so a crash is counted."""
