#!/usr/bin/env python3
"""Convert the Joe & Kuo (2008) Sobol' direction numbers to iuq-doe's compact binary table.

Source: S. Joe and F. Y. Kuo, "Constructing Sobol sequences with better two-dimensional
projections", SIAM J. Sci. Comput. 30, 2635-2654 (2008), table `new-joe-kuo-6.21201`
(21201 dimensions), as shipped with SciPy in `scipy/stats/_sobol_direction_numbers.npz`
(arrays `poly` and `vinit`; SciPy builds its direction numbers from exactly these arrays).

`poly[j]` is the primitive polynomial of dimension j written with its leading and trailing
coefficients (degree s = bit_length(poly) - 1), `vinit[j, :s]` the initial odd integers
m_1..m_s (m_k < 2^k). Dimension 0 is the van der Corput sequence (poly = 1, no m values).

Output format (all integers little-endian; "varint" = unsigned LEB128):

    magic       8 bytes  b"IUQJK621"
    dims        u32      number of dimensions (21201)
    block       u32      dimensions per block (1024)
    blocks      u32      ceil(dims / block)
    offsets     blocks x u32, byte offset of each block from the start of the payload
    payload     for each dimension j, in order:
                  varint((poly[j] - prev) / 2), prev = poly of dimension j-1, or 1 at the
                  start of a block (polynomials are odd and strictly increasing);
                  then s varints (m_k - 1) / 2 for k = 1..s (the m_k are odd).

Blocks let the Rust side decode only the dimensions a sequence needs. Usage:

    python3 make_direction_numbers.py [OUTPUT]   # default: new-joe-kuo-6.21201.bin next to this file
"""

import os
import struct
import sys

import numpy as np
import scipy

MAGIC = b"IUQJK621"
BLOCK = 1024


def varint(x: int) -> bytes:
    assert x >= 0
    out = bytearray()
    while True:
        byte = x & 0x7F
        x >>= 7
        if x:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def read_varint(buf: bytes, pos: int):
    value, shift = 0, 0
    while True:
        byte = buf[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos


def encode(poly: np.ndarray, vinit: np.ndarray) -> bytes:
    dims = len(poly)
    blocks = (dims + BLOCK - 1) // BLOCK
    payload = bytearray()
    offsets = []
    for j in range(dims):
        p = int(poly[j])
        if j % BLOCK == 0:
            offsets.append(len(payload))
            prev = 1
        assert p % 2 == 1 and p >= prev and (p - prev) % 2 == 0
        payload += varint((p - prev) // 2)
        prev = p
        s = p.bit_length() - 1
        for k in range(s):
            m = int(vinit[j, k])
            assert m % 2 == 1 and m < 2 ** (k + 1), (j, k, m)
            payload += varint((m - 1) // 2)
        assert all(int(v) == 0 for v in vinit[j, s:]) or j == 0
    header = MAGIC + struct.pack("<III", dims, BLOCK, blocks)
    header += b"".join(struct.pack("<I", o) for o in offsets)
    return header + bytes(payload)


def decode(data: bytes):
    assert data[:8] == MAGIC
    dims, block, blocks = struct.unpack_from("<III", data, 8)
    offsets = struct.unpack_from(f"<{blocks}I", data, 20)
    base = 20 + 4 * blocks
    polys, ms = [], []
    for b in range(blocks):
        pos = base + offsets[b]
        prev = 1
        for j in range(b * block, min(dims, (b + 1) * block)):
            delta, pos = read_varint(data, pos)
            p = prev + 2 * delta
            prev = p
            m = []
            for _ in range(p.bit_length() - 1):
                v, pos = read_varint(data, pos)
                m.append(2 * v + 1)
            polys.append(p)
            ms.append(m)
    return polys, ms


def main() -> None:
    here = os.path.dirname(os.path.abspath(__file__))
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "new-joe-kuo-6.21201.bin")
    src = os.path.join(os.path.dirname(scipy.__file__), "stats", "_sobol_direction_numbers.npz")
    table = np.load(src)
    poly, vinit = table["poly"], table["vinit"]
    assert poly.shape == (21201,), poly.shape
    data = encode(poly, vinit)
    polys, ms = decode(data)
    for j in range(len(poly)):
        s = int(poly[j]).bit_length() - 1
        assert polys[j] == int(poly[j])
        assert ms[j] == [int(v) for v in vinit[j, :s]]
    with open(out, "wb") as f:
        f.write(data)
    print(f"wrote {out}: {len(poly)} dimensions, {len(data)} bytes (scipy {scipy.__version__})")


if __name__ == "__main__":
    main()
