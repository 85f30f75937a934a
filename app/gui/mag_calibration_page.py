"""The calibration wizard's magnetometer page: turn the sensor through every direction, watch
the sphere's 80 sections fill in (MAVLink's MAG_CAL_PROGRESS), then the fit's residual and a
clear verdict (good, or redo with the reasons).

The maths is :mod:`app.core.magnetometer` (coverage and fit); the page only gathers the rows
(the field before calibration from the pipeline's field ring, the uncalibrated accelerometer
and gyroscope the wizard feeds), runs the fit when the user says the tour is done, and shows.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import (
    QCheckBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
    QWizardPage,
)

from app.core.earth_field import EarthField, earth_field
from app.core.field_check import ReferenceSettings
from app.core.magnetometer.coverage import (
    SECTIONS,
    CoverageTracker,
    section_centres,
    section_outlines,
)
from app.core.magnetometer.fit import MagFitResult, alignment_deg, fit_magnetometer
from app.core.ring_follower import RingFollower
from app.core.samples import SampleBlock
from app.gui import theme

MIN_FIT_COVERAGE = 0.25
"""The fit may be asked for from this coverage on (its verdict says redo below 75 %)."""


def _unit(az_el_deg: np.ndarray) -> np.ndarray:
    az, el = np.radians(az_el_deg[:, 0]), np.radians(az_el_deg[:, 1])
    return np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def hemisphere_polygons() -> list[tuple[int, np.ndarray]]:
    """Each section as (0 upper / 1 lower hemisphere, (M, 2) outline in a unit disc): the
    sphere seen from above (+z) and from below (-z, mirrored as seen from outside)."""
    out = []
    centres = section_centres()
    for index, outline in enumerate(section_outlines(8)):
        points = _unit(outline)
        lower = centres[index, 2] < 0
        if lower:
            points = points * np.array([1.0, -1.0, -1.0])  # seen from below
        xy = points[:, :2].copy()
        behind = points[:, 2] < 0  # past the rim: drawn on the rim
        norms = np.linalg.norm(xy[behind], axis=1, keepdims=True)
        xy[behind] = xy[behind] / np.maximum(norms, 1e-9)
        out.append((int(lower), xy))
    return out


class SphereCoverage(QWidget):
    """The sphere's 80 sections as two discs (upper and lower half), filled once covered."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._polygons = hemisphere_polygons()
        self.mask = np.zeros(SECTIONS, dtype=bool)
        self.setMinimumSize(280, 150)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        # A bound method: Qt drops the connection when the widget goes (a lambda would not).
        theme.notifier().changed.connect(self._on_theme)

    def _on_theme(self, _name: str = "") -> None:
        self.update()

    def set_mask(self, mask: np.ndarray) -> None:
        mask = np.asarray(mask, dtype=bool)
        if not np.array_equal(mask, self.mask):
            self.mask = mask.copy()
            self.update()

    def disc_rects(self) -> list[QRectF]:
        """Where the upper and the lower half are drawn."""
        label = self.fontMetrics().height() + 4
        size = max(20.0, min((self.width() - 30) / 2.0, self.height() - label - 8))
        top = label + (self.height() - label - size) / 2.0
        gap = (self.width() - 2 * size) / 3.0
        return [QRectF(gap, top, size, size), QRectF(2 * gap + size, top, size, size)]

    def paintEvent(self, _event) -> None:
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        rects = self.disc_rects()
        fill = QColor(theme.ACCENT)
        empty = QColor(theme.BASE_BG)
        edge = QPen(QColor(theme.BORDER), 1.0)
        for half, rect in enumerate(rects):
            painter.setPen(QPen(QColor(theme.TEXT_DIM)))
            painter.drawText(QRectF(rect.left(), 0, rect.width(), rect.top() - 4),
                             int(Qt.AlignmentFlag.AlignHCenter | Qt.AlignmentFlag.AlignBottom),
                             "upper half (+z)" if half == 0 else "lower half (−z)")
            painter.setPen(Qt.PenStyle.NoPen)
            painter.setBrush(QBrush(empty))
            painter.drawEllipse(rect)
        radius = rects[0].width() / 2.0
        for index, (half, xy) in enumerate(self._polygons):
            centre = rects[half].center()
            polygon = QPolygonF([QPointF(centre.x() + radius * x, centre.y() - radius * y)
                                 for x, y in xy])
            painter.setPen(edge)
            painter.setBrush(QBrush(fill if self.mask[index] else empty))
            painter.drawPolygon(polygon)
        painter.setBrush(Qt.BrushStyle.NoBrush)
        painter.setPen(QPen(QColor(theme.TEXT_DIM), 1.5))
        for rect in rects:
            path = QPainterPath()
            path.addEllipse(rect)
            painter.drawPath(path)
        painter.end()


class VerdictView(QWidget):
    """The fit's verdict in one glance: GOOD or REDO, the residual and the reasons."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.headline = QLabel()
        self.headline.setObjectName("magVerdict")
        font = self.headline.font()
        font.setPointSizeF(font.pointSizeF() * 1.6)
        font.setBold(True)
        self.headline.setFont(font)
        self.details = QLabel()
        self.details.setWordWrap(True)
        self.details.setTextFormat(Qt.TextFormat.RichText)
        layout.addWidget(self.headline)
        layout.addWidget(self.details)
        self.clear()

    def clear(self) -> None:
        self.headline.setText("")
        self.details.setText("")
        self.setVisible(False)

    def show_result(self, result: MagFitResult, expected: EarthField | None) -> None:
        cal = result.calibration
        good = result.good
        colour = theme.OK_GREEN if good else theme.WARN_AMBER
        self.headline.setText("Good — the magnetometer is calibrated" if good
                              else "Redo the tour")
        self.headline.setStyleSheet(f"color: {colour};")
        lines = [f"Fit residual <b>{cal.fitness_ut:.2f} µT RMS</b> · coverage "
                 f"{cal.coverage:.0%} of the sphere · {result.samples_used} field samples"]
        field_line = f"Field {cal.field_ut:.1f} µT, dip {cal.dip_deg:+.1f}°"
        if expected is not None:
            field_line += (f" (local WMM: {expected.total_ut:.1f} µT, dip "
                           f"{expected.dip_deg:+.1f}°)")
        lines.append(field_line)
        lines.append(f"Hard iron {', '.join(f'{v:+.1f}' for v in cal.hard_iron_ut)} µT · "
                     f"the chip turned {alignment_deg(cal.soft_iron):.2f}° against the "
                     f"accelerometer")
        if result.reasons:
            lines.append("<b>Why:</b><ul>" + "".join(f"<li>{r}</li>" for r in result.reasons)
                         + "</ul>")
        for note in result.notes:
            lines.append(f"<i>{note}</i>")
        self.details.setText("<br>".join(lines))
        self.setVisible(True)


class MagnetometerPage(QWizardPage):
    """Turn the sensor through every direction; the coverage fills in; Fit gives the verdict.

    The wizard feeds it uncalibrated blocks (:meth:`feed`); the field before calibration comes
    from ``pipeline.field`` (``raw_mag``). Complete with a good fit, or when the user leaves
    the magnetometer as it is.
    """

    resultChanged = Signal(object)  # MagFitResult | None

    def __init__(self, session, settings: ReferenceSettings | None = None) -> None:
        super().__init__()
        self.session = session
        self.settings = settings or ReferenceSettings()
        self.setTitle("Magnetometer")
        self.setSubTitle(
            "Turn the sensor slowly through every direction — roll it over, point each face "
            "up and down, and turn it round — until the sphere below is filled. Keep away from "
            "iron, magnets and running motors. Then press Fit.")
        layout = QVBoxLayout(self)
        self.sphere = SphereCoverage()
        layout.addWidget(self.sphere, 1)
        self.progress = QLabel()
        layout.addWidget(self.progress)
        buttons = QHBoxLayout()
        self.fit_button = QPushButton("Fit")
        self.fit_button.setToolTip("Fit hard iron, soft iron and the chip's turn to the tour")
        self.fit_button.clicked.connect(self.run_fit)
        self.restart_button = QPushButton("Restart the tour")
        self.restart_button.clicked.connect(self.restart)
        buttons.addWidget(self.fit_button)
        buttons.addWidget(self.restart_button)
        buttons.addStretch(1)
        layout.addLayout(buttons)
        self.verdict = VerdictView()
        layout.addWidget(self.verdict)
        self.skip = QCheckBox("Leave the magnetometer as it is")
        self.skip.toggled.connect(lambda _on: self.completeChanged.emit())
        layout.addWidget(self.skip)
        self.result: MagFitResult | None = None
        self.expected: EarthField | None = None
        self.error = ""
        self.restart()

    # -- gathering --------------------------------------------------------------------------------
    def restart(self) -> None:
        """Forget the tour so far and start gathering anew."""
        pipeline = self.session.pipeline
        self.tracker = CoverageTracker()
        self._field = RingFollower(lambda: pipeline.field, ["t", "raw_mag"])
        self._sample_parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._field_parts: list[tuple[np.ndarray, np.ndarray]] = []
        self.result, self.error = None, ""
        self.verdict.clear()
        self.sphere.set_mask(self.tracker.mask)
        self._show_progress()
        self.resultChanged.emit(None)
        self.completeChanged.emit()

    def initializePage(self) -> None:
        if self.result is None:
            self.restart()

    def feed(self, block: SampleBlock) -> None:
        """Take the wizard's next uncalibrated block and the field rows that came with it."""
        if self.result is not None:
            return  # the verdict stands until the tour restarts
        self._sample_parts.append((block.t_s, block.accel_m_s2, block.gyro_rad_s))
        rows = self._field.next_rows()
        if rows is not None:
            self._field_parts.append((rows["t"], rows["raw_mag"]))
            self.tracker.add(rows["raw_mag"])
            self.sphere.set_mask(self.tracker.mask)
        self._show_progress()

    def _show_progress(self) -> None:
        covered = int(np.count_nonzero(self.tracker.mask))
        self.progress.setText(
            f"Coverage: {covered} of {SECTIONS} sections ({self.tracker.fraction:.0%}) · "
            f"{self.tracker.rows} field samples")
        self.fit_button.setEnabled(self.result is None
                                   and self.tracker.fraction >= MIN_FIT_COVERAGE)

    def tour(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The tour's rows: times, field before calibration (NaN rows between field samples),
        accelerometer and gyroscope (uncalibrated)."""
        if not self._sample_parts:
            empty = np.zeros((0, 3))
            return np.zeros(0), empty, empty, empty
        t = np.concatenate([p[0] for p in self._sample_parts])
        accel = np.concatenate([p[1] for p in self._sample_parts])
        gyro = np.concatenate([p[2] for p in self._sample_parts])
        mag = np.full((len(t), 3), np.nan)
        if self._field_parts:
            field_t = np.concatenate([p[0] for p in self._field_parts])
            field = np.concatenate([p[1] for p in self._field_parts])
            index = np.clip(np.searchsorted(t, field_t), 0, max(len(t) - 1, 0))
            same = t[index] == field_t  # a field sample sits on its accelerometer row
            mag[index[same]] = field[same]
        return t, mag, accel, gyro

    # -- the fit ----------------------------------------------------------------------------------
    def run_fit(self) -> MagFitResult | None:
        """Fit the tour so far; the verdict is shown (a tour the fit refuses: the reason)."""
        t, mag, accel, gyro = self.tour()
        try:
            self.expected = earth_field(self.settings.place, self.settings.when)
        except ValueError:
            self.expected = None
        try:
            result = fit_magnetometer(mag, accel, t_s=t, gyro_rad_s=gyro,
                                      expected=self.expected)
        except ValueError as exc:
            self.error = str(exc)
            self.progress.setText(f"The fit refused this tour: {exc}. Go on turning, or "
                                  f"restart the tour.")
            return None
        self.result = result
        self.verdict.show_result(result, self.expected)
        self._show_progress()
        self.resultChanged.emit(result)
        self.completeChanged.emit()
        return result

    def isComplete(self) -> bool:
        return self.skip.isChecked() or (self.result is not None and self.result.good)

    @property
    def calibration(self):
        """The magnetometer's calibration to apply: a good fit's, else None."""
        if self.skip.isChecked() or self.result is None or not self.result.good:
            return None
        return self.result.calibration
