"""Argument types of the Taichi kernels: external arrays (torch tensors, zero-copy) by element type and rank.

The kernels take a processor's fixed tables and buffers grouped in argument packs (``ti.types.argpack``, defined
beside the kernels that own them, built once per runtime by ``taichi_setup.argpacks``). Taichi 1.7 names a pack's
arrays by their member names only and reserves every member name in the kernel: member names differ across the
packs of one kernel, and a kernel's locals do not reuse them."""

import taichi as ti

F32_1D = ti.types.ndarray(dtype=ti.f32, ndim=1)
F32_2D = ti.types.ndarray(dtype=ti.f32, ndim=2)
F32_3D = ti.types.ndarray(dtype=ti.f32, ndim=3)
F32_4D = ti.types.ndarray(dtype=ti.f32, ndim=4)
I32_1D = ti.types.ndarray(dtype=ti.i32, ndim=1)
I32_2D = ti.types.ndarray(dtype=ti.i32, ndim=2)
U8_1D = ti.types.ndarray(dtype=ti.u8, ndim=1)  # bool masks, as uint8 views (Taichi takes no torch bool)
# rows of 8 as vectors (the 8 x 8 CLT quadrants, kernels and low-pass tables, viewed row by row): one load or store
# per row, and the row's 8 frequencies as vector lanes
V8 = ti.types.vector(8, ti.f32)
V8_1D = ti.types.ndarray(dtype=V8, ndim=1)
V8_2D = ti.types.ndarray(dtype=V8, ndim=2)
