"""Registers, stack frame and static shared memory of each kernel in a CUDA cubin, read from its ELF sections: no
cuobjdump, CUDA toolkit or GPU needed (tpnet_gpu.runtime.cuda_aot reports them for the kernels it compiles).

Per kernel: ``registers`` and ``stack`` (bytes per thread) are the .nv.info attributes EIATTR_REGCOUNT (0x2f) and
EIATTR_FRAME_SIZE (0x11), as cuobjdump -elf names them; ``static_smem`` is the size of the ``.nv.shared.<kernel>``
section, bytes per block. For Warp kernels that is 4 B x block_dim (tile.h's ``smem_base``) plus, on sm_90, 1 KiB
(read off the sizes: 256 B at 64 threads on sm_80, 1280 B on sm_90). Warp's tile storage is *dynamic* shared memory,
requested at launch; its size is in the module's ``.meta`` file, not in the cubin.
"""

from __future__ import annotations

import struct

_EIATTR = {0x2F: "registers", 0x11: "stack"}


def kernel_resources(data: bytes) -> dict:
    """{symbol: {registers, stack, static_smem}} of every Warp kernel entry (``*_cuda_kernel_*``) of an ELF cubin."""
    (shoff,) = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    secs = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]

    def cstr(offset: int) -> str:
        return data[offset:data.index(b"\0", offset)].decode()

    names = [cstr(secs[shstrndx][4] + s[0]) for s in secs]
    symtab = secs[names.index(".symtab")]  # entries of 24 bytes; the first field is the name's offset
    symbols = [cstr(secs[symtab[6]][4] + struct.unpack_from("<I", data, symtab[4] + i * 24)[0])
               for i in range(symtab[5] // 24)]
    rows: dict = {}
    for name, (_name, _type, _flags, _addr, off, size, *_rest) in zip(names, secs):
        if name.startswith(".nv.shared.") and not name.startswith(".nv.shared.reserved"):
            rows.setdefault(name[len(".nv.shared."):], {})["static_smem"] = size
        if not name.startswith(".nv.info"):
            continue
        pos = off
        while pos < off + size:  # attribute records: format byte, attribute byte, payload
            fmt, attr = data[pos], data[pos + 1]
            if fmt == 0x04:  # EIFMT_SVAL: u16 size + payload (u32 symbol index, u32 value)
                (length,) = struct.unpack_from("<H", data, pos + 2)
                if attr in _EIATTR and length >= 8:
                    index, value = struct.unpack_from("<II", data, pos + 4)
                    if index < len(symbols):
                        rows.setdefault(symbols[index], {})[_EIATTR[attr]] = value
                pos += 4 + length
            else:  # EIFMT_NVAL: 2 bytes; EIFMT_BVAL, EIFMT_HVAL: 4 bytes
                pos += 2 if fmt == 0x01 else 4
    return {k: v for k, v in rows.items() if "_cuda_kernel_" in k}
