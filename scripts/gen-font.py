#!/usr/bin/env python3
"""Writes src/figures/font.txt: the figures' 7x14 bitmap font, rendered from DejaVu Sans Mono
at 12 px (the Bitstream Vera / DejaVu licence allows embedding the rendering).

Needs Pillow and the font file (Debian: fonts-dejavu-core):
    python3 -m venv /tmp/fontenv && /tmp/fontenv/bin/pip install pillow
    /tmp/fontenv/bin/python scripts/gen-font.py [PATH/TO/DejaVuSansMono.ttf]

Each glyph is drawn white on black into a 7x14 cell with its top-left at (0, -1), and each
pixel's coverage kept to 4 bits (0-15, one hex digit).
"""
import sys
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

W, H = 7, 14
# ASCII, then the symbols the figures and pages use.
CHARS = [chr(c) for c in range(0x20, 0x7F)] + list("ψ′±°−·—βμωσχ×≤≥→")

font_path = sys.argv[1] if len(sys.argv) > 1 else "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf"
font = ImageFont.truetype(font_path, 12)
out = [
    "# The figures' bitmap font: 7x14 px cells rendered from DejaVu Sans Mono 12 px by",
    "# scripts/gen-font.py (do not edit by hand). Per glyph: its code point, then 14 rows of",
    "# 7 hex digits, each a pixel's coverage 0-f.",
]
for ch in CHARS:
    im = Image.new("L", (W, H), 0)
    ImageDraw.Draw(im).text((0, -1), ch, font=font, fill=255, anchor="la")
    px = [p >> 4 for p in im.tobytes()]
    out.append(f"U+{ord(ch):04X}")
    for r in range(H):
        out.append("".join(f"{p:x}" for p in px[r * W:(r + 1) * W]))
target = Path(__file__).resolve().parent.parent / "src/figures/font.txt"
target.write_text("\n".join(out) + "\n", encoding="utf-8")
print(f"{target}: {len(CHARS)} glyphs")
