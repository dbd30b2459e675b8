"""TPNET's training data: rendered scenes measured into network layers and targets (``dataset``), built here or
spread over Ray workers (``ray_jobs``; also ``tpnet process --ray``). The training loop is ``tpnet_gpu.net.train``."""
