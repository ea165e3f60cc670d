#!/usr/bin/env python3
"""Writes the textures of scenes/tiled-cornell-box.obj (scenes/textures/*.png), made by the
radcast project and released under CC0 1.0 (scenes/textures/LICENSE.md). Standard library
only; the output is byte-for-byte reproducible: python3 scripts/make-example-textures.py"""

import struct
import zlib
from pathlib import Path


def write_png(path, width, height, texel):
    """An 8-bit sRGB RGB PNG whose texel (x, y), y down from the top, is texel(x, y)."""
    rows = b"".join(
        b"\0" + bytes(c for x in range(width) for c in texel(x, y)) for y in range(height)
    )

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
    png += chunk(b"sRGB", b"\0") + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")
    path.write_bytes(png)


def floor_tiles(x, y):
    """Four by four tiles, alternating warm and cool grey, with dark grout between them."""
    size = 32
    if x % size < 2 or y % size < 2:
        return (60, 56, 52)
    return (214, 200, 178) if (x // size + y // size) % 2 == 0 else (150, 158, 170)


def brick_wall(x, y):
    """Running-bond bricks, each course offset by half a brick, in mortar."""
    course, brick = 16, 32
    row = y // course
    shift = (brick // 2) * (row % 2)
    if y % course < 2 or (x + shift) % brick < 2:
        return (200, 196, 188)
    tone = ((x + shift) // brick * 7 + row * 3) % 5
    return (150 + 6 * tone, 70 + 3 * tone, 52 + 2 * tone)


folder = Path(__file__).resolve().parent.parent / "scenes" / "textures"
folder.mkdir(exist_ok=True)
write_png(folder / "floor-tiles.png", 128, 128, floor_tiles)
write_png(folder / "brick-wall.png", 128, 128, brick_wall)
