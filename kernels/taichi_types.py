"""Argument types of the Taichi kernels: external arrays (torch tensors, zero-copy) by element type and rank."""

import taichi as ti

F32_1D = ti.types.ndarray(dtype=ti.f32, ndim=1)
F32_2D = ti.types.ndarray(dtype=ti.f32, ndim=2)
F32_3D = ti.types.ndarray(dtype=ti.f32, ndim=3)
F32_4D = ti.types.ndarray(dtype=ti.f32, ndim=4)
I32_1D = ti.types.ndarray(dtype=ti.i32, ndim=1)
I32_2D = ti.types.ndarray(dtype=ti.i32, ndim=2)
U8_1D = ti.types.ndarray(dtype=ti.u8, ndim=1)  # bool masks, as uint8 views (Taichi takes no torch bool)
