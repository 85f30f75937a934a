"""Text contrast per WCAG 2.x: the high-contrast theme passes level AA (4.5:1) on every text
colour; the other themes on every text colour of an enabled control."""

from __future__ import annotations

import re
from importlib.resources import files

import pytest
from PySide6.QtGui import QPalette

from app.core.contrast import (
    WCAG_AA_TEXT,
    blend,
    contrast_ratio,
    parse_colour,
    relative_luminance,
)
from app.gui import theme


def test_relative_luminance_of_known_colours():
    assert relative_luminance("#000000") == 0.0
    assert relative_luminance("#ffffff") == pytest.approx(1.0)
    # sRGB primaries weigh 0.2126, 0.7152, 0.0722.
    assert relative_luminance("#ff0000") == pytest.approx(0.2126)
    assert relative_luminance("#00ff00") == pytest.approx(0.7152)
    assert relative_luminance("#0000ff") == pytest.approx(0.0722)
    # Mid grey #808080: ((128/255 + 0.055) / 1.055) ** 2.4 = 0.2159.
    assert relative_luminance("#808080") == pytest.approx(0.2159, abs=1e-4)
    # The linear part of the curve, below 0.04045: 10/255/12.92.
    assert relative_luminance("#0a0a0a") == pytest.approx(10 / 255 / 12.92)


def test_contrast_ratio_of_known_pairs():
    assert contrast_ratio("#000000", "#ffffff") == pytest.approx(21.0)
    assert contrast_ratio("#ffffff", "#000000") == pytest.approx(21.0)  # symmetric
    assert contrast_ratio("#777777", "#777777") == pytest.approx(1.0)
    # WebAIM's checker: #767676 on white is 4.54:1 (the lightest grey that passes AA),
    # #777777 4.48:1 (fails); #0000ff on white 8.59:1.
    assert contrast_ratio("#767676", "#ffffff") == pytest.approx(4.54, abs=0.01)
    assert contrast_ratio("#777777", "#ffffff") == pytest.approx(4.48, abs=0.01)
    assert contrast_ratio("#0000ff", "#ffffff") == pytest.approx(8.59, abs=0.01)
    assert contrast_ratio("#fff", "#000") == pytest.approx(21.0)


def test_colour_parsing_and_blending():
    assert parse_colour("#1a2B3c") == (0x1A, 0x2B, 0x3C)
    with pytest.raises(ValueError, match="not a #rrggbb colour"):
        parse_colour("grey")
    assert blend("#ffffff", "#000000", 0.5) == "#808080"
    assert blend("#ff0000", "#0000ff", 1.0) == "#ff0000"


def _stylesheet_pairs() -> list[tuple[str, str | None, str]]:
    """(text colour, background colour or None, selector) of every rule of the stylesheet
    that sets a text colour."""
    template = (files("resources") / "styles" / "instrument.qss").read_text(encoding="utf-8")
    template = re.sub(r"/\*.*?\*/", "", template, flags=re.S)
    pairs = []
    for selector, body in re.findall(r"([^{}]+)\{([^}]*)\}", template):
        text = re.search(r"(?<![-\w])color:\s*@([A-Z_]+)", body)
        background = re.search(r"(?<![-\w])background(?:-color)?:\s*@([A-Z_]+)", body)
        if text:
            pairs.append((text.group(1), background.group(1) if background else None,
                          " ".join(selector.split())))
    return pairs


def test_the_declared_pairs_cover_every_text_colour_of_the_stylesheet():
    """A new ``color:`` in the stylesheet must be declared in theme.TEXT_ON_BACKGROUND (with
    its background, when the rule sets one), or the contrast check would not see it."""
    declared = {(fg, bg) for fg, bg, _ in theme.TEXT_ON_BACKGROUND}
    texts = {fg for fg, _ in declared}
    pairs = _stylesheet_pairs()
    assert len(pairs) >= 20  # the parser found the rules
    for fg, bg, selector in pairs:
        fg = "ALARM_RED" if fg == "ALARM_STATE" else fg
        bg = "ALARM_RED" if bg == "ALARM_STATE" else bg
        assert fg in texts, f"{selector}: text colour {fg} not declared"
        if bg is not None:
            assert (fg, bg) in declared, f"{selector}: {fg} on {bg} not declared"


def _palette_pairs(t: theme.Theme) -> list[tuple[str, str, str]]:
    """Every text role of the theme's palette on its background role."""
    palette = theme.palette(t)
    role, group = QPalette.ColorRole, QPalette.ColorGroup
    pairs = []
    for text_role, background_role in (
        (role.WindowText, role.Window), (role.Text, role.Base), (role.ButtonText, role.Button),
        (role.ToolTipText, role.ToolTipBase), (role.HighlightedText, role.Highlight),
        (role.PlaceholderText, role.Base), (role.Link, role.Base),
    ):
        pairs.append((palette.color(group.Active, text_role).name(),
                      palette.color(group.Active, background_role).name(),
                      f"{text_role.name} on {background_role.name}"))
    for text_role, background_role in ((role.WindowText, role.Window), (role.Text, role.Base),
                                       (role.ButtonText, role.Button)):
        pairs.append((palette.color(group.Disabled, text_role).name(),
                      palette.color(group.Disabled, background_role).name(),
                      f"disabled {text_role.name} on {background_role.name}"))
    return pairs


def _all_pairs(t: theme.Theme) -> list[tuple[str, float]]:
    declared = [(f"{fg} on {bg} ({where})", contrast_ratio(getattr(t, fg), getattr(t, bg)))
                for fg, bg, where in theme.TEXT_ON_BACKGROUND]
    palette = [(where, contrast_ratio(fg, bg)) for fg, bg, where in _palette_pairs(t)]
    # The bubble's captions are painted at 90 % opacity on its plate.
    caption = blend(t.TEXT_DIM, t.VIAL_PLATE, 230 / 255)
    painted = [("bubble caption TEXT_DIM at 90 % on VIAL_PLATE",
                contrast_ratio(caption, t.VIAL_PLATE))]
    return declared + palette + painted


def test_high_contrast_theme_passes_wcag_aa_on_every_text_colour():
    ratios = _all_pairs(theme.HIGH_CONTRAST)
    failing = [f"{where}: {ratio:.2f}" for where, ratio in ratios if ratio < WCAG_AA_TEXT]
    assert not failing, failing
    assert min(ratio for _, ratio in ratios) >= WCAG_AA_TEXT
    print(f"\nhigh-contrast: {len(ratios)} text colours, lowest "
          f"{min(ratio for _, ratio in ratios):.2f}:1")


@pytest.mark.parametrize("theme_name", ["dark", "light"])
def test_other_themes_pass_wcag_aa_on_enabled_text(theme_name):
    """WCAG exempts the text of disabled controls (SC 1.4.3, "incidental"); every other text
    colour of the dark and light themes passes AA too. Their figures are printed."""
    t = theme.THEMES[theme_name]
    ratios = _all_pairs(t)
    enabled = [(where, ratio) for where, ratio in ratios
               if "DISABLED" not in where and not where.startswith("disabled")]
    failing = [f"{where}: {ratio:.2f}" for where, ratio in enabled if ratio < WCAG_AA_TEXT]
    assert not failing, failing
    disabled = [ratio for where, ratio in ratios if (where, ratio) not in enabled]
    print(f"\n{theme_name}: {len(enabled)} enabled text colours, lowest "
          f"{min(r for _, r in enabled):.2f}:1; disabled text {min(disabled):.2f}:1 "
          f"to {max(disabled):.2f}:1 (exempt)")
