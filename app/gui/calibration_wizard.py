"""The calibration wizard: gyro bias, accelerometer poses, results; non-modal.

The wizard is a controller and a set of views: it pulls *uncalibrated* samples from the
pipeline (:class:`~app.core.raw_feed.RawSampleFeed`) on a timer, feeds the procedures of
:mod:`app.core.calibration_procedures` and shows their state. All maths lives there. The result
reaches the pipeline only when the user presses Finish (``profileAccepted``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QFont, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QDoubleSpinBox,
    QFormLayout,
    QGridLayout,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QLineEdit,
    QListView,
    QListWidget,
    QProgressBar,
    QPushButton,
    QRadioButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
    QWizard,
    QWizardPage,
)

from app.core.calibration_procedures import (
    FACE_HINTS,
    FACES,
    FREE,
    SIX_POSITION,
    AccelFit,
    CalibrationFitError,
    CalibrationProfile,
    GyroBiasCalibration,
    GyroBiasState,
    PoseCapture,
    SensorNoise,
    SensorSettings,
    StillnessDetector,
    compare_poses,
    fit_free_poses,
    fit_six_position,
    make_profile,
    worsening,
)
from app.core.devices import DeviceInfo
from app.core.raw_feed import RawSampleFeed
from app.gui import theme
from app.gui.file_dialogs import save_file_name
from app.gui.mag_calibration_page import MagnetometerPage  # magview (#31)
from app.services.session import DeviceSession

FEED_INTERVAL_MS = 100


class StillnessGauge(QWidget):
    """Two bars: accelerometer and gyro motion relative to the still threshold (1 = limit)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        layout = QFormLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.accel_bar = QProgressBar()
        self.gyro_bar = QProgressBar()
        for bar in (self.accel_bar, self.gyro_bar):
            bar.setRange(0, 200)
            bar.setTextVisible(False)
            bar.setMaximumHeight(10)
        self.state_label = QLabel("—")
        layout.addRow("Accelerometer motion", self.accel_bar)
        layout.addRow("Gyroscope motion", self.gyro_bar)
        layout.addRow("", self.state_label)

    def show_state(self, accel_ratio: float, gyro_ratio: float, still: bool) -> None:
        for bar, ratio in ((self.accel_bar, accel_ratio), (self.gyro_bar, gyro_ratio)):
            value = 200 if not math.isfinite(ratio) else min(200, round(100 * ratio))
            bar.setValue(value)
            colour = theme.OK_GREEN if value <= 100 else theme.WARN_AMBER
            bar.setStyleSheet(f"QProgressBar::chunk {{ background: {colour}; }}")
        self.state_label.setText("Still" if still else "Moving — keep it still")
        colour = theme.OK_GREEN if still else theme.WARN_AMBER
        self.state_label.setStyleSheet(f"color: {colour};")


class PoseHint(QWidget):
    """A picture of the expected pose: the board seen from the side, its up axis as an arrow."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.face = "+z"
        self.setMinimumSize(220, 170)

    def set_face(self, face: str) -> None:
        self.face = face
        self.update()

    def paintEvent(self, _event) -> None:
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        w, h = self.width(), self.height()
        # The box the board rests on.
        box = QRectF(w * 0.2, h * 0.62, w * 0.6, h * 0.3)
        painter.setPen(QPen(QColor(theme.BORDER), 1.5))
        painter.setBrush(QColor(theme.PANEL_BG))
        painter.drawRect(box)
        # The board: flat for z faces, standing on an edge for x / y faces.
        axis, sign = self.face[1], self.face[0]
        board = QPainterPath()
        if axis == "z":
            board.addRoundedRect(QRectF(w * 0.3, h * 0.53, w * 0.4, h * 0.09), 3, 3)
        else:
            board.addRoundedRect(QRectF(w * 0.46, h * 0.22, w * 0.08, h * 0.40), 3, 3)
        painter.setBrush(QColor("#2f6f4f"))
        painter.setPen(QPen(QColor("#4cc38a"), 1.2))
        painter.drawPath(board)
        # The chip marks the +z side.
        painter.setBrush(QColor("#111"))
        painter.setPen(Qt.PenStyle.NoPen)
        if axis == "z":
            chip_y = h * 0.50 if sign == "+" else h * 0.62
            painter.drawRect(QRectF(w * 0.47, chip_y, w * 0.06, h * 0.03))
        else:
            painter.drawRect(QRectF(w * 0.54, h * 0.38, w * 0.02, h * 0.08))
        # The up arrow, labelled with the axis that must point up.
        top = h * 0.06
        base = h * 0.2 if axis != "z" else h * 0.46
        painter.setPen(QPen(QColor(theme.ACCENT), 3))
        painter.drawLine(QPointF(w * 0.5, base), QPointF(w * 0.5, top + 10))
        painter.setBrush(QColor(theme.ACCENT))
        painter.drawPolygon(
            QPolygonF([QPointF(w * 0.5, top), QPointF(w * 0.47, top + 12),
                       QPointF(w * 0.53, top + 12)])
        )
        font = QFont(self.font())
        font.setPointSizeF(font.pointSizeF() * 1.6)
        font.setBold(True)
        painter.setFont(font)
        painter.setPen(QColor(theme.TEXT))
        painter.drawText(QRectF(w * 0.55, top, w * 0.4, 30), f"{self.face.upper()} up")
        painter.end()


class _Page(QWizardPage):
    """A page the wizard's timer feeds with uncalibrated blocks while it is current."""

    def feed(self, block) -> None:  # pragma: no cover - overridden
        pass


class IntroPage(_Page):
    def __init__(self, info: DeviceInfo | None) -> None:
        super().__init__()
        self.setTitle("Calibrate the sensor")
        self.setSubTitle(
            "About three minutes: hold still for the gyroscope, then place the board on the six "
            "faces of a box (or in 12 free orientations). Nothing changes until you press Finish."
        )
        layout = QVBoxLayout(self)
        device = "no device connected" if info is None else (
            f"{info.name} — id {info.unique_id} — {info.odr_hz:.1f} Hz, "
            f"±{info.accel_fs_g} g, ±{info.gyro_fs_dps} °/s"
        )
        self.device_label = QLabel(device)
        self.device_label.setWordWrap(True)
        layout.addWidget(self.device_label)
        self.six_button = QRadioButton("Six faces of a box (recommended: best accuracy)")
        self.free_button = QRadioButton("Free orientations, no box (ellipsoid fit, 12 poses)")
        self.skip_button = QRadioButton("Gyroscope bias only")
        self.six_button.setChecked(True)
        group = QButtonGroup(self)
        for button in (self.six_button, self.free_button, self.skip_button):
            group.addButton(button)
            layout.addWidget(button)
        # magview (#31): the magnetometer's tour, offered when the device has one.
        has_field = info is not None and info.magnetometer is not None
        self.mag_box = QCheckBox("Magnetometer too: turn the sensor through every direction")
        self.mag_box.setChecked(has_field)
        self.mag_box.setVisible(has_field)
        layout.addWidget(self.mag_box)
        self.mag_only_button = QRadioButton(
            "Magnetometer only (keeps the accelerometer's and gyroscope's calibration)")
        self.mag_only_button.setVisible(has_field)
        group.addButton(self.mag_only_button)
        layout.insertWidget(layout.indexOf(self.skip_button) + 1, self.mag_only_button)
        self.mag_only_button.toggled.connect(
            lambda on: on and self.mag_box.setChecked(True))
        form = QFormLayout()
        self.gyro_seconds = QDoubleSpinBox()
        self.gyro_seconds.setRange(2.0, 120.0)
        self.gyro_seconds.setValue(10.0)
        self.gyro_seconds.setSuffix(" s")
        form.addRow("Hold still for the gyroscope", self.gyro_seconds)
        layout.addLayout(form)
        note = QLabel(
            "Accuracy follows how square the box is: a face tilted by 1° shifts the result by "
            "about 0.5° of misalignment. Any box with flat, square faces does; a machinist's "
            "block is best."
        )
        note.setObjectName("dimLabel")
        note.setWordWrap(True)
        layout.addWidget(note)
        layout.addStretch(1)

    @property
    def method(self) -> str:
        if self.free_button.isChecked():
            return FREE
        if self.skip_button.isChecked() or self.mag_only:
            return ""
        return SIX_POSITION

    @property
    def mag_only(self) -> bool:
        """Only the magnetometer's tour (magview #31): the rest of the calibration stays."""
        return self.mag_only_button.isChecked()


class GyroPage(_Page):
    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__()
        self._wizard = wizard
        self.setTitle("Gyroscope bias")
        self.setSubTitle("Put the board down on a firm surface and do not touch it.")
        layout = QVBoxLayout(self)
        self.gauge = StillnessGauge()
        layout.addWidget(self.gauge)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        layout.addWidget(self.progress)
        self.message = QLabel()
        self.message.setWordWrap(True)
        layout.addWidget(self.message)
        self.result_label = QLabel()
        self.result_label.setWordWrap(True)
        layout.addWidget(self.result_label)
        restart = QPushButton("Start again")
        restart.clicked.connect(self.initializePage)
        layout.addWidget(restart, 0, Qt.AlignmentFlag.AlignLeft)
        layout.addStretch(1)
        self.procedure: GyroBiasCalibration | None = None

    def initializePage(self) -> None:
        intro = self._wizard.intro
        self.procedure = GyroBiasCalibration(
            self._wizard.new_detector(), duration_s=intro.gyro_seconds.value()
        )
        self.result_label.setText("")
        self.progress.setValue(0)
        self.message.setText(self.procedure.message)
        self.completeChanged.emit()

    def feed(self, block) -> None:
        procedure = self.procedure
        if procedure is None:
            return
        state = procedure.update(block)
        detector = procedure.detector
        self.gauge.show_state(detector.accel_ratio, detector.gyro_ratio, detector.is_still)
        self.progress.setValue(round(1000 * procedure.progress))
        text = procedure.message
        if procedure.restarts:
            text += f"  (restarted {procedure.restarts}× because the board moved)"
        self.message.setText(text)
        if state is GyroBiasState.DONE and procedure.result is not None:
            self.message.setText("Done. The bias is applied when you press Finish.")
            result = procedure.result
            bias = ", ".join(f"{v:+.4f}" for v in result.bias_dps)
            sigma = max(result.std_error_dps)
            self.result_label.setText(
                f"Gyro bias ({bias}) °/s  ±{sigma:.4f} °/s, at {result.temperature_degc:.1f} °C"
            )
            self.completeChanged.emit()

    def isComplete(self) -> bool:
        return self.procedure is not None and self.procedure.state is GyroBiasState.DONE


class PosesPage(_Page):
    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__()
        self._wizard = wizard
        self.setTitle("Accelerometer poses")
        layout = QGridLayout(self)
        self.hint = PoseHint()
        layout.addWidget(self.hint, 0, 0)
        side = QVBoxLayout()
        self.instruction = QLabel()
        self.instruction.setWordWrap(True)
        side.addWidget(self.instruction)
        self.faces = QListWidget()
        self.faces.setMaximumHeight(140)
        side.addWidget(self.faces)
        layout.addLayout(side, 0, 1)
        self.gauge = StillnessGauge()
        layout.addWidget(self.gauge, 1, 0, 1, 2)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        layout.addWidget(self.progress, 2, 0, 1, 2)
        buttons = QHBoxLayout()
        self.capture_button = QPushButton("Capture now")
        self.capture_button.setToolTip("Capture as soon as the board is still")
        self.capture_button.clicked.connect(lambda: self.capture and self.capture.request_capture())
        self.undo_button = QPushButton("Remove last pose")
        self.undo_button.clicked.connect(self._remove_last)
        buttons.addWidget(self.capture_button)
        buttons.addWidget(self.undo_button)
        buttons.addStretch(1)
        layout.addLayout(buttons, 3, 0, 1, 2)
        self.rejection = QLabel()
        self.rejection.setWordWrap(True)
        self.rejection.setStyleSheet(f"color: {theme.WARN_AMBER}; font-weight: bold;")
        self.rejection.hide()
        layout.addWidget(self.rejection, 4, 0, 1, 2)
        self.events = QListWidget()
        # A rejection names the face, the angle and what to do: wrapped, read whole (it was
        # cut at the list's right edge behind a sideways scroll bar).
        self.events.setWordWrap(True)
        self.events.setResizeMode(QListView.ResizeMode.Adjust)
        self.events.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        layout.addWidget(self.events, 5, 0, 1, 2)
        self.capture: PoseCapture | None = None

    def initializePage(self) -> None:
        mode = self._wizard.intro.method
        self.capture = PoseCapture(self._wizard.new_detector(), mode=mode)
        self.events.clear()
        self.rejection.hide()
        self.setSubTitle(
            "Place the board as shown and let go: each pose is captured automatically after "
            "about 3 s of stillness." if mode == SIX_POSITION else
            "Hold the board still in at least 12 clearly different orientations, "
            "about 3 s each (rest it against something)."
        )
        self._refresh()

    def _remove_last(self) -> None:
        if self.capture and self.capture.poses:
            pose = self.capture.remove_pose(len(self.capture.poses) - 1)
            self.events.insertItem(0, f"Removed the {pose.face} pose")
            self._refresh()

    def feed(self, block) -> None:
        capture = self.capture
        if capture is None:
            return
        for event in capture.update(block):
            if event.accepted and event.pose is not None:
                text = f"✓ Captured {event.pose.face} up"
                self.rejection.hide()
            else:
                text = f"✗ {event.reason}"
                self.rejection.setText(f"✗ {event.reason}")
                self.rejection.show()
            self.events.insertItem(0, text)
            self.completeChanged.emit()
        detector = capture.detector
        self.gauge.show_state(detector.accel_ratio, detector.gyro_ratio, detector.is_still)
        self.progress.setValue(round(1000 * capture.progress))
        self._refresh()

    def _refresh(self) -> None:
        capture = self.capture
        if capture is None:
            return
        self.faces.clear()
        if capture.mode == SIX_POSITION:
            done = set(capture.captured_faces)
            for face in FACES:
                mark = "✓" if face in done else "·"
                self.faces.addItem(f"{mark}  {face} up — {FACE_HINTS[face]}")
            missing = capture.missing_faces
            if missing:
                self.hint.set_face(missing[0])
                self.instruction.setText(
                    f"Next: <b>{missing[0]} up</b> — {FACE_HINTS[missing[0]]}. "
                    f"State: {capture.state.value}."
                )
            else:
                self.instruction.setText("All six faces captured. Press Next for the results.")
        else:
            for pose in capture.poses:
                self.faces.addItem(f"✓  pose {len(self.faces) + 1}: nearest face {pose.face}")
            self.instruction.setText(
                f"{len(capture.poses)} of {capture.min_poses} poses. State: {capture.state.value}."
            )

    def isComplete(self) -> bool:
        return self.capture is not None and self.capture.enough


class ResultsPage(_Page):
    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__()
        self._wizard = wizard
        self.setTitle("Results")
        layout = QVBoxLayout(self)
        self.summary = QLabel()
        self.summary.setWordWrap(True)
        layout.addWidget(self.summary)
        self.parameters = QTableWidget(0, 4)
        self.parameters.setHorizontalHeaderLabels(["Parameter", "x", "y", "z"])
        self.comparison = QTableWidget(0, 3)
        self.comparison.setHorizontalHeaderLabels(["Pose", "Tilt error before", "after"])
        for table in (self.parameters, self.comparison):
            table.verticalHeader().setVisible(False)
            table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
            table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
            layout.addWidget(table)
        form = QFormLayout()
        self.name_edit = QLineEdit()
        form.addRow("Profile name", self.name_edit)
        layout.addLayout(form)
        self.insist = QCheckBox("Apply it anyway (the tilt error gets worse)")
        self.insist.setToolTip("Finish applies a calibration that reads worse than before only "
                               "when this is ticked; redoing the poses is better")
        self.insist.toggled.connect(lambda _checked: self.completeChanged.emit())
        self.insist.hide()
        layout.addWidget(self.insist)
        self.report_button = QPushButton("Save report (HTML or PDF)…")
        self.report_button.clicked.connect(lambda: self.save_report())
        layout.addWidget(self.report_button, 0, Qt.AlignmentFlag.AlignLeft)
        self.fit: AccelFit | None = None
        self.tilt_comparison = None
        self.error: str = ""
        self.worse: str = ""

    def initializePage(self) -> None:
        wizard = self._wizard
        self.fit, self.error, self.tilt_comparison = None, "", None
        self.worse = ""
        self.insist.setChecked(False)
        gyro = wizard.gyro_page.procedure.result if wizard.gyro_page.procedure else None
        rows: list[tuple[str, list[str]]] = []
        if gyro is not None:
            rows.append(("Gyro bias (°/s)", [f"{v:+.4f}" for v in gyro.bias_dps]))
            rows.append(("  ± (°/s)", [f"{v:.4f}" for v in gyro.std_error_dps]))
        comparison_rows: list[tuple[str, str, str]] = []
        capture = wizard.poses_page.capture
        if wizard.intro.method and capture is not None:
            try:
                fit = (fit_six_position(capture.poses) if capture.mode == SIX_POSITION
                       else fit_free_poses(capture.poses))
            except CalibrationFitError as exc:
                self.error = str(exc)
            else:
                self.fit = fit
                rows.append(("Accel bias (mg)", [f"{v:+.2f}" for v in fit.bias_mg]))
                rows.append(("  ± (mg)", [f"{v:.2f}" for v in fit.bias_std_mg]))
                rows.append(("Scale error (%)", [f"{100 * v:+.3f}" for v in fit.scale_error]))
                rows.append(("  ± (%)", [f"{100 * v:.3f}" for v in fit.scale_error_std]))
                calibration = fit.to_calibration(gyro)
                comparison = compare_poses(capture.poses, calibration)
                self.tilt_comparison = comparison
                self.worse = worsening(comparison)
                for row in comparison.rows():
                    comparison_rows.append(
                        (str(row["pose"]), f"{float(row['error_before_deg']):.3f}°",
                         f"{float(row['error_after_deg']):.3f}°")
                    )
        self.parameters.setRowCount(len(rows))
        for r, (title, values) in enumerate(rows):
            for c, text in enumerate([title, *values]):
                self.parameters.setItem(r, c, QTableWidgetItem(text))
        self.comparison.setRowCount(len(comparison_rows))
        for r, cells in enumerate(comparison_rows):
            for c, text in enumerate(cells):
                self.comparison.setItem(r, c, QTableWidgetItem(text))
        if self.error:
            self.summary.setText(f"<b>The fit failed:</b> {self.error} Go back and redo poses.")
        elif self.fit is not None and self.worse:
            fit = self.fit
            self.summary.setText(
                f"<b style='color:{theme.WARN_AMBER}'>Not applied: {self.worse}</b> Go back and "
                "redo the poses (each flat on a face of a box on a level table). Finish applies "
                f"it only if you tick the box below. Accelerometer fit ({fit.method}, "
                f"{fit.n_poses} poses): residual {fit.residual_norm_rms_mg:.3f} mg RMS."
            )
        elif self.fit is not None:
            fit = self.fit
            self.summary.setText(
                f"Accelerometer fit ({fit.method}, {fit.n_poses} poses): residual "
                f"{fit.residual_norm_rms_mg:.3f} mg RMS of |a| − 1 g. "
                "Press Finish to save this profile for the device and apply it."
            )
        elif wizard.intro.mag_only:  # magview (#31)
            self.summary.setText("The accelerometer's and gyroscope's calibration stays as it "
                                 "is.")
        else:
            self.summary.setText("Gyroscope bias measured. Press Finish to save and apply it.")
        magnetometer = self._magnetometer()  # magview (#31)
        if magnetometer is not None:
            self.summary.setText(self.summary.text() + (
                f" Magnetometer: residual {magnetometer.fitness_ut:.2f} µT RMS, coverage "
                f"{magnetometer.coverage:.0%} (saved with the profile)."))
        info = wizard.info
        self.name_edit.setText(f"{info.name if info else 'sensor'} calibration")
        self.insist.setVisible(bool(self.worse))
        self.completeChanged.emit()

    def isComplete(self) -> bool:
        """Finish needs a result, and the user's insistence when it makes the tilt worse."""
        return not self.error and (not self.worse or self.insist.isChecked())

    def save_report(self, path: str | None = None) -> str | None:
        """Write the calibration report (app.documents.calibration_report) for this result."""
        from app.documents.calibration_report import report_from_parts, write_report

        profile = self.profile()
        if self.fit is None or self.tilt_comparison is None or profile is None:
            self.summary.setText("A report needs an accelerometer fit of a connected device.")
            return None
        if path is None:
            path, _ = save_file_name(
                self, "Save calibration report", f"calibration-{profile.device_unique_id}.pdf",
                "PDF (*.pdf);;HTML (*.html)")
            if not path:
                return None
        wizard = self._wizard
        gyro = wizard.gyro_page.procedure.result if wizard.gyro_page.procedure else None
        capture = wizard.poses_page.capture
        info = wizard.info
        report = report_from_parts(
            self.fit, np.zeros(3) if gyro is None else gyro.bias_rad_s,
            np.full(3, np.nan) if gyro is None else gyro.std_error_rad_s, self.tilt_comparison,
            profile, {"name": info.name if info else ""}, "calibration wizard",
            rejected=[f"t = {e.time_s:.1f} s: {e.reason}" for e in
                      (capture.events if capture else []) if not e.accepted],
            gyro_source="" if gyro is None else f"gyro step ({gyro.duration_s:.1f} s still)")
        report.tilt_reference = "the reference orientation, else the nominal faces"
        if self._magnetometer() is not None:  # magview (#31)
            from app.documents.calibration_report import magnetometer_section_html

            report.magnetometer_html = magnetometer_section_html(
                wizard.mag_page.result, wizard.mag_page.expected)
        write_report(report, Path(path))
        self.summary.setText(self.summary.text() + f" Report saved: {path}")
        return path

    def _magnetometer(self):
        """The magnetometer page's good fit, when its tour was part of this run (magview)."""
        wizard = self._wizard
        if not wizard.intro.mag_box.isChecked():
            return None
        return wizard.mag_page.calibration

    def profile(self) -> CalibrationProfile | None:
        wizard = self._wizard
        info = wizard.info
        if info is None:
            return None
        gyro = wizard.gyro_page.procedure.result if wizard.gyro_page.procedure else None
        name = self.name_edit.text().strip() or "calibration"
        if self.fit is not None:
            calibration = self.fit.to_calibration(gyro, name=name)
            residuals = dict(self.fit.summary())
            method = self.fit.method
            temperature = self.fit.temperature_degc
        elif wizard.intro.mag_only:  # magview (#31): the calibration in use, plus the field
            from dataclasses import replace

            calibration = replace(wizard.session.pipeline.calibration, name=name)
            residuals, method, temperature = {}, "magnetometer", math.nan
        else:
            from app.core.calibration import SensorCalibration

            bias = np.zeros(3) if gyro is None else gyro.bias_rad_s
            calibration = SensorCalibration(gyro_bias_rad_s=bias, name=name)
            residuals, method = {}, "gyro-bias"
            temperature = math.nan if gyro is None else gyro.temperature_degc
        if gyro is not None:
            residuals["gyro_bias_std_dps"] = [float(v) for v in gyro.std_error_dps]
        magnetometer = self._magnetometer()  # magview (#31): a good fit goes in the profile
        if magnetometer is not None:
            calibration = calibration.with_magnetometer(magnetometer)
            residuals["magnetometer_fitness_uT"] = float(magnetometer.fitness_ut)
        return make_profile(
            info.unique_id, calibration,
            SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps, info.sensor),
            method=method, temperature_degc=temperature, residuals=residuals,
        )


class CalibrationWizard(QWizard):
    """Non-modal: the live views stay usable while it runs."""

    profileAccepted = Signal(object)  # CalibrationProfile

    def __init__(self, session: DeviceSession, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Calibration wizard")
        self.setWizardStyle(QWizard.WizardStyle.ModernStyle)
        self.setModal(False)
        self.session = session
        self.info = session.device_info
        self.feed_source = RawSampleFeed(session.pipeline)
        self.intro = IntroPage(self.info)
        self.gyro_page = GyroPage(self)
        self.poses_page = PosesPage(self)
        self.mag_page = MagnetometerPage(session)  # magview (#31)
        self.results_page = ResultsPage(self)
        self.page_ids = {page: self.addPage(page) for page in (
            self.intro, self.gyro_page, self.poses_page, self.mag_page, self.results_page)}
        self.resize(720, 640)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self._feed)
        self.timer.start(FEED_INTERVAL_MS)
        self.finished.connect(self.timer.stop)
        session.disconnected.connect(self._on_disconnected)

    def nextId(self) -> int:
        current = self.currentId()
        ids = self.page_ids
        following = super().nextId()
        if current == ids[self.intro] and self.intro.mag_only:
            following = ids[self.mag_page]  # magview (#31): no gyro step, no poses
        if current == ids[self.gyro_page] and not self.intro.method:
            following = ids[self.mag_page]  # gyro only: skip the poses
        if following == ids[self.mag_page] and not self.intro.mag_box.isChecked():
            following = ids[self.results_page]  # magview (#31): no magnetometer tour
        return following

    def new_detector(self) -> StillnessDetector:
        info = self.info
        noise = SensorNoise.lsm6dsox(
            info.odr_hz if info else 104.0, info.accel_fs_g if info else 4,
            info.gyro_fs_dps if info else 250,
        )
        return StillnessDetector(noise)

    def _feed(self) -> None:
        block = self.feed_source.next_block()
        page = self.currentPage()
        if block is not None and isinstance(page, _Page | MagnetometerPage):
            page.feed(block)

    def _on_disconnected(self, reason: str) -> None:
        if self.isVisible():
            self.intro.device_label.setText(
                "The device disconnected" + (f": {reason}" if reason else "")
                + ". Reconnect it to go on; the steps restart when data flows again."
            )

    def accept(self) -> None:
        if not self.results_page.isComplete():
            return  # a worse result is applied only when the user insists
        profile = self.results_page.profile()
        if profile is not None:
            self.profileAccepted.emit(profile)
        super().accept()
