"""Find text that does not fit its widget: elided, cut at an edge or squeezed flat.

:func:`clipped_texts` walks the visible widgets under a root and measures each text with the
widget's font (``QFontMetrics.horizontalAdvance``) against the room the widget gives it:
labels, buttons, check boxes, combo boxes, spin boxes, tab titles, table headers and cells.
A widget cut off at the side by a parent that cannot scroll sideways counts too, as does a
field less tall than its text. The clipped-text test runs it on every dock and dialog.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from PySide6 import QtGui
from PySide6.QtCore import Qt
from PySide6.QtGui import QFontMetrics
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractScrollArea,
    QAbstractSpinBox,
    QCheckBox,
    QComboBox,
    QHeaderView,
    QLabel,
    QLineEdit,
    QRadioButton,
    QStyle,
    QStyleOptionComboBox,
    QTabBar,
    QTableWidget,
    QWidget,
)

from app.gui.elided_label import ElidedLabel

BUTTON_PADDING_PX = 8
"""Room a push or tool button needs beside its text (frame and margins), at the least."""
CELL_PADDING_PX = 6
"""Room a table cell or header section needs beside its text."""


@dataclass
class FitReport:
    """What a walk found: how many widgets were measured and which texts do not fit."""

    checked: int = 0
    problems: list[str] = field(default_factory=list)

    def add(self, other: FitReport) -> None:
        self.checked += other.checked
        self.problems.extend(other.problems)


def describe(widget: QWidget) -> str:
    """A path that finds ``widget`` again: class and object names up to its window."""
    parts = []
    current: QWidget | None = widget
    while current is not None and len(parts) < 6:
        name = current.objectName()
        parts.append(f"{type(current).__name__}#{name}" if name else type(current).__name__)
        if current.isWindow():
            break
        current = current.parentWidget()
    return " < ".join(parts)


def _plain_button_text(text: str) -> str:
    return text.replace("&&", "\0").replace("&", "").replace("\0", "&")


def _widest_line(metrics: QFontMetrics, text: str) -> int:
    return max((metrics.horizontalAdvance(line) for line in text.split("\n")), default=0)


def _cut_sideways(widget: QWidget) -> bool:
    """Whether a parent that cannot scroll sideways cuts ``widget`` at its left or right."""
    parent = widget.parentWidget()
    while parent is not None:
        if isinstance(parent, QAbstractScrollArea) and (
            parent.horizontalScrollBarPolicy() != Qt.ScrollBarPolicy.ScrollBarAlwaysOff
        ):
            return False  # it scrolls: nothing is lost
        if parent.isWindow():
            break
        parent = parent.parentWidget()
    visible = widget.visibleRegion().boundingRect()
    return not visible.isEmpty() and visible.width() < widget.width() - 1


def _label_problem(label: QLabel) -> str | None:
    if isinstance(label, ElidedLabel):
        return f"elided {label.text()!r}" if label.isElided() else None
    text = label.text()
    if not text or (label.pixmap() is not None and not label.pixmap().isNull()):
        return None
    room = label.contentsRect()
    if label.wordWrap():
        needed = label.heightForWidth(room.width() + label.contentsMargins().left()
                                      + label.contentsMargins().right())
        if needed > label.height() + 1:
            return f"wrapped text needs {needed} px of height, has {label.height()}"
        return None
    if label.textFormat() == Qt.TextFormat.RichText or (
        label.textFormat() == Qt.TextFormat.AutoText and QtGui.Qt.mightBeRichText(text)
    ):
        hint = label.minimumSizeHint()
        if label.width() < hint.width() - 1 or label.height() < hint.height() - 1:
            return f"rich text needs {hint.width()}x{hint.height()}, has {label.width()}x" \
                   f"{label.height()}"
        return None
    needed = _widest_line(label.fontMetrics(), text) + 2 * label.margin() + max(0, label.indent())
    if needed > room.width() + 1:
        return f"{text[:40]!r} needs {needed} px, has {room.width()}"
    if label.fontMetrics().height() > room.height() + 2:
        return f"{text[:40]!r} needs {label.fontMetrics().height()} px of height, has " \
               f"{room.height()}"
    return None


def _button_problem(button: QAbstractButton) -> str | None:
    text = _plain_button_text(button.text())
    if not text:
        return None
    metrics = button.fontMetrics()
    needed = _widest_line(metrics, text)
    if not button.icon().isNull():
        needed += button.iconSize().width() + 4
    style = button.style()
    if isinstance(button, QCheckBox | QRadioButton):
        needed += style.pixelMetric(QStyle.PixelMetric.PM_IndicatorWidth, None, button)
        needed += style.pixelMetric(QStyle.PixelMetric.PM_CheckBoxLabelSpacing, None, button)
    else:
        needed += BUTTON_PADDING_PX
    if needed > button.width():
        return f"{text[:40]!r} needs {needed} px, has {button.width()}"
    if metrics.height() > button.height():
        return f"{text[:40]!r} needs {metrics.height()} px of height, has {button.height()}"
    return None


def _combo_problem(combo: QComboBox) -> str | None:
    if combo.isEditable():
        return None  # typed text scrolls in its field
    option = QStyleOptionComboBox()
    combo.initStyleOption(option)
    room = combo.style().subControlRect(
        QStyle.ComplexControl.CC_ComboBox, option, QStyle.SubControl.SC_ComboBoxEditField, combo)
    text = combo.currentText()
    needed = combo.fontMetrics().horizontalAdvance(text)
    if not combo.itemIcon(combo.currentIndex()).isNull():
        needed += combo.iconSize().width() + 4
    if needed > room.width():
        return f"{text[:40]!r} needs {needed} px, has {room.width()}"
    if room.height() < combo.fontMetrics().height():
        return f"{text[:40]!r} squeezed to {room.height()} px of height"
    return None


def _spin_problem(spin: QAbstractSpinBox) -> str | None:
    edit = spin.findChild(QLineEdit)
    if edit is None:
        return None
    text = spin.text()
    needed = spin.fontMetrics().horizontalAdvance(text) + 4
    room = edit.contentsRect().width()
    if needed > room:
        return f"{text!r} needs {needed} px, has {room}"
    if edit.contentsRect().height() < spin.fontMetrics().height():
        return f"{text!r} squeezed to {edit.contentsRect().height()} px of height (needs " \
               f"{spin.fontMetrics().height()})"
    return None


def _tab_problems(bar: QTabBar) -> list[str]:
    found = []
    metrics = bar.fontMetrics()
    for index in range(bar.count()):
        if not bar.isTabVisible(index):
            continue
        text = _plain_button_text(bar.tabText(index))
        rect = bar.tabRect(index)
        needed = metrics.horizontalAdvance(text) + CELL_PADDING_PX
        if needed > rect.width():
            found.append(f"tab {text!r} needs {needed} px, has {rect.width()}")
        beyond = rect.right() > bar.width() or rect.left() < 0
        if beyond and not bar.usesScrollButtons():
            found.append(f"tab {text!r} is out of the bar and cannot be scrolled to")
    return found


def _header_problems(header: QHeaderView) -> list[str]:
    model = header.model()
    if model is None or header.orientation() != Qt.Orientation.Horizontal:
        return []
    found = []
    metrics = header.fontMetrics()
    margin = header.style().pixelMetric(QStyle.PixelMetric.PM_HeaderMargin, None, header)
    for section in range(header.count()):
        if header.isSectionHidden(section):
            continue
        text = model.headerData(section, Qt.Orientation.Horizontal,
                                Qt.ItemDataRole.DisplayRole)
        if not text:
            continue
        needed = _widest_line(metrics, str(text)) + 2 * margin
        if header.isSortIndicatorShown() and header.sortIndicatorSection() == section:
            needed += header.style().pixelMetric(QStyle.PixelMetric.PM_HeaderMarkSize, None,
                                                 header)
        if needed > header.sectionSize(section):
            found.append(f"header {str(text)[:40]!r} needs {needed} px, has "
                         f"{header.sectionSize(section)}")
    return found


def _cell_problems(table: QTableWidget) -> list[str]:
    if table.wordWrap():
        return []
    found = []
    metrics = table.fontMetrics()
    for row in range(table.rowCount()):
        if table.isRowHidden(row):
            continue
        for column in range(table.columnCount()):
            item = table.item(row, column)
            if item is None or not item.text() or table.isColumnHidden(column):
                continue
            needed = _widest_line(metrics, item.text()) + CELL_PADDING_PX
            if not item.icon().isNull():
                needed += table.iconSize().width() + 4
            if needed > table.columnWidth(column):
                found.append(f"cell {item.text()[:40]!r} needs {needed} px, has "
                             f"{table.columnWidth(column)}")
    return found


def problems_of(widget: QWidget) -> list[str] | None:
    """What does not fit in ``widget`` (None: not a widget with text of its own)."""
    found: list[str] = []
    if isinstance(widget, QLabel):
        problem = _label_problem(widget)
    elif isinstance(widget, QAbstractButton):
        problem = _button_problem(widget)
    elif isinstance(widget, QComboBox):
        problem = _combo_problem(widget)
    elif isinstance(widget, QAbstractSpinBox):
        problem = _spin_problem(widget)
    elif isinstance(widget, QTabBar):
        found.extend(_tab_problems(widget))
        problem = None
    elif isinstance(widget, QHeaderView):
        found.extend(_header_problems(widget))
        problem = None
    elif isinstance(widget, QTableWidget):
        found.extend(_cell_problems(widget))
        problem = None
    else:
        return None
    if problem:
        found.append(problem)
    # A tab bar's own parts (its scroll arrows) slide out of it by design.
    in_tab_bar = isinstance(widget, QTabBar) or isinstance(widget.parentWidget(), QTabBar)
    if not in_tab_bar and _cut_sideways(widget):
        found.append(f"cut at the side ({widget.visibleRegion().boundingRect().width()} of "
                     f"{widget.width()} px visible)")
    return found


def clipped_texts(root: QWidget, skip: tuple[type, ...] = ()) -> FitReport:
    """Measure every visible text widget under ``root`` (``root`` included); widgets of a
    class in ``skip`` are left out with their children."""
    report = FitReport()
    stack = [root]
    while stack:
        widget = stack.pop()
        if not widget.isVisible() or widget.width() <= 0 or widget.height() <= 0:
            continue
        if skip and isinstance(widget, skip):
            continue
        found = problems_of(widget)
        if found is not None:
            report.checked += 1
            report.problems.extend(f"{describe(widget)}: {text}" for text in found)
        if isinstance(widget, QAbstractSpinBox | QComboBox):
            continue  # their line edits are measured with them
        stack.extend(child for child in widget.children() if isinstance(child, QWidget)
                     and not child.isWindow())
    return report
