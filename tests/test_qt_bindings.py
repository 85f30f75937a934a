"""Guard against Qt binding releases that corrupt the interpreter.

PySide6 6.12.0 under Python 3.11 drops a reference to ``None`` on every Qt call that returns
nothing; the process then aborts within seconds. pyproject.toml excludes that release; this
test catches a future one with the same fault.
"""

from __future__ import annotations

import sys

from PySide6.QtWidgets import QLabel


def test_void_qt_calls_do_not_leak_or_steal_references_to_none(qapp):
    label = QLabel()
    before = sys.getrefcount(None)
    for _ in range(1000):
        label.setText("x")
        label.update()
    after = sys.getrefcount(None)
    assert abs(after - before) < 50
