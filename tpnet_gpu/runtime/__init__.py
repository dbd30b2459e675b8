"""What the kernels run on: Warp's and Taichi's set-up (devices, caches, threads), the CUDA ahead-of-time compile
check and its cubins, and the progress bars and log verbosity of the long commands."""
