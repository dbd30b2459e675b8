"""Outputs: folders and files written whole or not at all, one run at a time (``folder``, ``claim``), a frame's
maps and files (``frame_outputs``), point clouds (``pointcloud``) and the labelled figures (``figures``,
matplotlib on use)."""

from tpnet_gpu.outputs.folder import check, claimed, claimed_file, output_file, output_folder

__all__ = ["check", "claimed", "claimed_file", "output_file", "output_folder"]
