"""LZF decompression (liblzf's format, as PCL's binary_compressed PCD files use it), in pure Python."""
from __future__ import annotations


def lzf_decompress(data: bytes, expected_size: int) -> bytes:
    """Decompress LZF; raises ValueError on a corrupt stream or when the output size is not ``expected_size``."""
    out = bytearray()
    i, n = 0, len(data)
    try:
        while i < n:
            ctrl = data[i]
            i += 1
            if ctrl < 32:  # literal run of ctrl + 1 bytes
                run = data[i:i + ctrl + 1]
                if len(run) != ctrl + 1:
                    raise IndexError
                out += run
                i += ctrl + 1
                continue
            length = ctrl >> 5
            if length == 7:
                length += data[i]
                i += 1
            ref = len(out) - ((ctrl & 0x1F) << 8) - data[i] - 1
            i += 1
            length += 2
            if ref < 0:
                raise IndexError
            if ref + length <= len(out):
                out += out[ref:ref + length]
            else:  # overlapping back-reference: repeat the pattern
                for k in range(length):
                    out.append(out[ref + k])
    except IndexError:
        raise ValueError("corrupt LZF data (reference or run outside the buffer)") from None
    if len(out) != expected_size:
        raise ValueError(f"corrupt LZF data: {len(out)} bytes decompressed, header says {expected_size}")
    return bytes(out)
