"""Render the application icon (resources/icons/inclinometer.svg) for the desktop and bundles.

    .venv/bin/python packaging/linux/render_icons.py

Writes, from the one SVG, with Qt's own SVG renderer (no other tool needed):

- ``packaging/linux/icons/hicolor/NxN/apps/APP_ID.png`` at the freedesktop sizes, plus
  ``scalable/apps/APP_ID.svg`` (a copy), installed by ``make install-desktop``;
- ``packaging/icons/inclinometer.ico`` (Windows executable) and ``inclinometer.icns`` (macOS
  app), used by ``packaging/inclinometer.spec``.

The outputs are committed; run this again after changing the SVG.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

PACKAGING = Path(__file__).resolve().parent.parent
ROOT = PACKAGING.parent
SVG = ROOT / "resources" / "icons" / "inclinometer.svg"
APP_ID = "org.inclinometer.Inclinometer"
SIZES = (16, 22, 24, 32, 48, 64, 128, 256, 512)


def render(renderer, size: int):
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QImage, QPainter

    image = QImage(size, size, QImage.Format.Format_ARGB32_Premultiplied)
    image.fill(Qt.GlobalColor.transparent)
    painter = QPainter(image)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing)
    painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform)
    renderer.render(painter)
    painter.end()
    return image


def main() -> int:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtGui import QGuiApplication, QImageWriter
    from PySide6.QtSvg import QSvgRenderer

    _app = QGuiApplication.instance() or QGuiApplication(sys.argv[:1])
    renderer = QSvgRenderer(str(SVG))
    if not renderer.isValid():
        print(f"render_icons: cannot read {SVG}", file=sys.stderr)
        return 1
    hicolor = PACKAGING / "linux" / "icons" / "hicolor"
    for size in SIZES:
        folder = hicolor / f"{size}x{size}" / "apps"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{APP_ID}.png"
        if not render(renderer, size).save(str(path), "PNG"):
            print(f"render_icons: could not write {path}", file=sys.stderr)
            return 1
    scalable = hicolor / "scalable" / "apps"
    scalable.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(SVG, scalable / f"{APP_ID}.svg")
    bundle_icons = PACKAGING / "icons"
    bundle_icons.mkdir(exist_ok=True)
    for name, fmt, size in (("inclinometer.ico", b"ico", 256), ("inclinometer.icns", b"icns", 512)):
        writer = QImageWriter(str(bundle_icons / name), fmt)
        if not writer.write(render(renderer, size)):
            print(f"render_icons: could not write {name}: {writer.errorString()}", file=sys.stderr)
            return 1
    print(f"render_icons: {len(SIZES)} PNG sizes, the SVG, .ico and .icns written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
