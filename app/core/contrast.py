"""Contrast of text colours against their backgrounds, per WCAG 2.x.

WCAG's level AA asks for a contrast ratio of at least 4.5:1 for normal text. The ratio is
``(L1 + 0.05) / (L2 + 0.05)`` of the lighter and darker colours' relative luminances
(https://www.w3.org/TR/WCAG21/#dfn-contrast-ratio).
"""

from __future__ import annotations

WCAG_AA_TEXT = 4.5
"""Level AA's least contrast ratio for normal-size text."""


def _channel(value_8bit: int) -> float:
    """An sRGB channel (0-255) in linear light, WCAG 2.x's formula."""
    c = value_8bit / 255.0
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def parse_colour(colour: str) -> tuple[int, int, int]:
    """``#rrggbb`` (or ``#rgb``) as 8-bit red, green, blue; ValueError otherwise."""
    text = colour.strip().lstrip("#")
    if len(text) == 3:
        text = "".join(c * 2 for c in text)
    if len(text) != 6 or any(c not in "0123456789abcdefABCDEF" for c in text):
        raise ValueError(f"not a #rrggbb colour: {colour!r}")
    return int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16)


def relative_luminance(colour: str) -> float:
    """WCAG relative luminance of ``#rrggbb``: 0 (black) to 1 (white)."""
    r, g, b = (_channel(v) for v in parse_colour(colour))
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


def contrast_ratio(foreground: str, background: str) -> float:
    """WCAG contrast ratio of two colours, 1 (equal) to 21 (black on white); symmetric."""
    lighter, darker = sorted(
        (relative_luminance(foreground), relative_luminance(background)), reverse=True)
    return (lighter + 0.05) / (darker + 0.05)


def blend(foreground: str, background: str, alpha: float) -> str:
    """``foreground`` drawn at opacity ``alpha`` (0-1) over ``background``, as ``#rrggbb``
    (blended per channel in sRGB, as a painter does)."""
    fg, bg = parse_colour(foreground), parse_colour(background)
    mixed = (round(f * alpha + b * (1.0 - alpha)) for f, b in zip(fg, bg, strict=True))
    return "#" + "".join(f"{v:02x}" for v in mixed)
