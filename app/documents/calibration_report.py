"""The calibration report: one self-contained HTML or PDF document per calibrated unit.

It holds the device id, date, sensor settings, temperature, the fitted parameters with
their uncertainties, per-pose residuals and tilt errors before/after, a plot of those, the
rejected capture attempts and, for a simulated unit, the recovered parameters against its
truth; with temperature compensation, its coefficients and a bias-vs-temperature plot.
HTML embeds its plots as data URIs; PDF goes through Qt's own printing support
(``QTextDocument.print_`` on a ``QPdfWriter``): no new dependency.

Used by ``inclinometer calibrate --report FILE``, ``inclinometer calibrate-temperature
--report FILE`` and the wizard's Finish page.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import QBuffer, QByteArray, QIODevice, QMarginsF, QPointF, QRectF, Qt, QUrl
from PySide6.QtGui import (
    QColor,
    QFont,
    QImage,
    QPageLayout,
    QPageSize,
    QPainter,
    QPdfWriter,
    QPen,
    QPolygonF,
    QTextDocument,
)

from app.core.version import __version__

PLOT_NAME = "tilt-errors.png"
TEMPERATURE_PLOT_NAME = "bias-vs-temperature.png"
BEFORE_COLOUR = "#d9822b"
AFTER_COLOUR = "#2b7bd9"
AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")


@dataclass
class TemperatureSection:
    """The temperature compensation: coefficients and the bias-vs-temperature data.

    ``points`` and ``curves`` map a sensor title (``"Gyroscope"``, ``"Accelerometer"``) to its
    unit and the data: points (temperatures (B,), change from b(T0) (B, 3)) and the fitted
    change ``k1 d + k2 d^2`` as (k1 (3,), k2 (3,)), all in the display unit.
    """

    reference_temp_degc: float
    temp_min_degc: float
    temp_max_degc: float
    rows: list[tuple[str, str, str, Sequence[float], Sequence[float] | None]]
    """(sensor, coefficient, unit, values x y z, 1-sigma x y z or None)."""
    models: dict[str, str]
    criterion: str
    points: dict[str, tuple[str, np.ndarray, np.ndarray]]
    curves: dict[str, tuple[np.ndarray, np.ndarray]]
    summary: list[str] = field(default_factory=list)
    truth: list[tuple[str, str, Sequence[float], Sequence[float]]] = field(default_factory=list)


@dataclass
class CalibrationReport:
    """What the report shows (plain values; build with :func:`report_from_offline`)."""

    device_id: str
    created_utc: str
    method: str
    source: str
    settings: dict[str, Any]
    temperature_degc: float
    parameters: list[tuple[str, str, Sequence[float], Sequence[float] | None]]
    """(name, unit, values x y z, 1-sigma x y z or None)."""
    poses: list[tuple[str, float, float, float]]
    """(label, |a| - g in mg, tilt error before, after in degrees)."""
    residual_norm_rms_mg: float
    tilt_reference: str
    rejected: list[str] = field(default_factory=list)
    truth: list[tuple[str, str, Sequence[float], Sequence[float]]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    temperature: TemperatureSection | None = None
    magnetometer_html: str = ""  # magview (#31): magnetometer_section_html(...), "" without one


def temperature_section(fit, calibration, unit_errors: dict[str, Any] | None = None,
                        summary: Sequence[str] = ()) -> TemperatureSection:
    """The report's temperature section from a :class:`~app.core.calibration_procedures.
    temperature.TemperatureFit` and the calibration that carries its terms."""
    from app.core.calibration_procedures.temperature import QUADRATIC, truth_of
    from app.core.samples import STANDARD_GRAVITY_M_S2

    model = calibration.temperature
    mdps = 180.0 / math.pi * 1e3
    mg = 1e3 / STANDARD_GRAVITY_M_S2
    t0 = model.reference_temp_degc
    rows = [
        ("Gyroscope", "b0 at T0", "°/s", np.degrees(calibration.gyro_bias_rad_s), None),
        ("Gyroscope", "k1", "m°/s/°C", model.gyro_k1 * mdps, fit.gyro.k1_std * mdps),
        ("Gyroscope", "k2", "m°/s/°C²", model.gyro_k2 * mdps,
         fit.gyro.k2_std * mdps if fit.gyro.degree == QUADRATIC else None),
        ("Accelerometer", "b0 at T0", "mg", calibration.accel_bias_m_s2 * mg, None),
        ("Accelerometer", "k1", "mg/°C", model.accel_k1 * mg, fit.accel.k1_std * mg),
        ("Accelerometer", "k2", "mg/°C²", model.accel_k2 * mg,
         fit.accel.k2_std * mg if fit.accel.degree == QUADRATIC else None),
    ]
    points, curves = {}, {}
    for title, unit, sensor, values, scale, k1, k2 in (
        ("Gyroscope", "m°/s", fit.gyro, fit.bin_gyro_rad_s, mdps, model.gyro_k1, model.gyro_k2),
        ("Accelerometer", "mg", fit.accel, fit.bin_accel_m_s2, mg, model.accel_k1,
         model.accel_k2),
    ):
        # Each bin's value less its pose's reading at T0 (the curve through the new T0).
        at_t0 = sensor.change(np.array([t0 - fit.reference_temp_degc]))[0]
        change = values - sensor.intercepts[fit.bin_pose] - at_t0
        points[title] = (unit, fit.bin_temp_degc.copy(), change * scale)
        curves[title] = (np.asarray(k1) * scale, np.asarray(k2) * scale)
    truth = []
    if unit_errors:
        true = truth_of(fit, unit_errors)
        truth = [("Gyroscope k1", "m°/s/°C", model.gyro_k1 * mdps, true.gyro_k1 * mdps),
                 ("Accelerometer k1 (in this pose)", "mg/°C", model.accel_k1 * mg,
                  true.accel_k1 * mg)]
    models = {"Gyroscope": "quadratic" if fit.gyro.degree == QUADRATIC else "linear",
              "Accelerometer": "quadratic" if fit.accel.degree == QUADRATIC else "linear"}
    return TemperatureSection(
        reference_temp_degc=t0, temp_min_degc=fit.temp_min_degc,
        temp_max_degc=fit.temp_max_degc, rows=rows, models=models,
        criterion=fit.summary()["criterion"], points=points, curves=curves,
        summary=list(summary), truth=truth)


def report_from_temperature(fit, calibration, profile, device, source: str,
                            unit_errors: dict[str, Any] | None = None,
                            summary: Sequence[str] = ()) -> CalibrationReport:
    """A report of ``inclinometer calibrate-temperature``: the temperature section only."""
    s = profile.settings
    return CalibrationReport(
        device_id=profile.device_unique_id, created_utc=profile.created_utc,
        method="temperature compensation", source=source,
        settings={"sensor": s.sensor, "odr_hz": s.odr_hz, "accel_fs_g": s.accel_fs_g,
                  "gyro_fs_dps": s.gyro_fs_dps, "device": (device or {}).get("name", "")},
        temperature_degc=fit.reference_temp_degc, parameters=[], poses=[],
        residual_norm_rms_mg=math.nan, tilt_reference="",
        notes=list(fit.notes),
        temperature=temperature_section(fit, calibration, unit_errors, summary))


def report_from_parts(fit, gyro_bias_rad_s, gyro_std_rad_s, comparison, profile, device,
                      source: str, rejected: Sequence[str] = (), truth=None,
                      notes: Sequence[str] = (), gyro_source: str = "") -> CalibrationReport:
    """A report from an accelerometer fit, a gyro bias, a tilt comparison and the profile."""
    s = profile.settings
    parameters = [
        ("Accelerometer bias", "mg", fit.bias_mg, fit.bias_std_mg),
        ("Accelerometer scale error", "%", 100 * fit.scale_error, 100 * fit.scale_error_std),
        ("Frame rotation", "°", fit.frame_rotation_deg, None),
        ("Gyroscope bias", "°/s", np.degrees(gyro_bias_rad_s), np.degrees(gyro_std_rad_s)),
    ]
    nonortho = fit.non_orthogonality_deg
    parameters.insert(2, ("Non-orthogonality xy, xz, yz", "°",
                          [nonortho["xy"], nonortho["xz"], nonortho["yz"]], None))
    poses = [
        (label, float(fit.norm_errors_mg[i]), float(comparison.before.inclination_deg[i]),
         float(comparison.after.inclination_deg[i]))
        for i, label in enumerate(comparison.labels)
    ]
    all_notes = list(notes)
    if gyro_source:
        all_notes.insert(0, f"Gyroscope bias from the {gyro_source}.")
    return CalibrationReport(
        device_id=profile.device_unique_id, created_utc=profile.created_utc,
        method=fit.method, source=source,
        settings={"sensor": s.sensor, "odr_hz": s.odr_hz, "accel_fs_g": s.accel_fs_g,
                  "gyro_fs_dps": s.gyro_fs_dps, "device": (device or {}).get("name", "")},
        temperature_degc=fit.temperature_degc, parameters=parameters, poses=poses,
        residual_norm_rms_mg=fit.residual_norm_rms_mg,
        tilt_reference=getattr(comparison, "reference", "") or "",
        rejected=list(rejected),
        truth=[(name, unit, rec, tru) for name, unit, rec, tru in (truth.rows if truth else [])],
        notes=all_notes,
    )


def report_from_offline(result, profile, device, source: str,
                        unit_errors: dict[str, Any] | None = None) -> CalibrationReport:
    """The report of a headless run (:class:`~app.core.calibration_procedures.offline.
    OfflineCalibration`), with the simulator's truth when ``unit_errors`` is given."""
    from app.core.calibration_procedures.offline import compare_with_truth

    truth = compare_with_truth(result, unit_errors) if unit_errors else None
    report = report_from_parts(
        result.fit, result.gyro_bias_rad_s, result.gyro_bias_std_rad_s, result.comparison,
        profile, device, source,
        rejected=[f"t = {e.time_s:.1f} s: {e.reason}" for e in result.rejected],
        truth=truth, notes=result.notes, gyro_source=result.gyro_source)
    report.tilt_reference = ("the reference orientation" if result.comparison_reference ==
                             "truth" else "the nominal faces")
    return report


# -- the plot --------------------------------------------------------------------------------------
def tilt_plot(report: CalibrationReport, width: int = 900, height: int = 320) -> QImage:
    """Bars of the tilt error before and after per pose, on a log scale (degrees)."""
    image = QImage(width, height, QImage.Format.Format_ARGB32)
    image.fill(QColor("white"))
    painter = QPainter(image)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing)
    font = QFont()
    font.setPixelSize(13)
    painter.setFont(font)
    left, right, top, bottom = 70, 20, 30, 50
    plot = QRectF(left, top, width - left - right, height - top - bottom)
    values = [v for _, _, b, a in report.poses for v in (b, a) if v > 0 and math.isfinite(v)]
    low = 10 ** math.floor(math.log10(min(values))) if values else 1e-4
    high = 10 ** math.ceil(math.log10(max(values))) if values else 10.0
    low, high = min(low, high / 10), max(high, low * 10)

    def y_of(value: float) -> float:
        value = max(value, low)
        frac = (math.log10(value) - math.log10(low)) / (math.log10(high) - math.log10(low))
        return plot.bottom() - frac * plot.height()

    painter.setPen(QPen(QColor("#cccccc"), 1))
    exponent = round(math.log10(low))
    while 10.0**exponent <= high * 1.0001:
        y = y_of(10.0**exponent)
        painter.drawLine(QPointF(plot.left(), y), QPointF(plot.right(), y))
        painter.setPen(QColor("#333333"))
        painter.drawText(QRectF(0, y - 9, left - 8, 18),
                         Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter,
                         f"{10.0**exponent:g}°")
        painter.setPen(QPen(QColor("#cccccc"), 1))
        exponent += 1
    n = max(1, len(report.poses))
    slot = plot.width() / n
    bar = slot * 0.32
    for i, (label, _, before, after) in enumerate(report.poses):
        x = plot.left() + i * slot + slot * 0.16
        for value, colour, offset in ((before, BEFORE_COLOUR, 0.0), (after, AFTER_COLOUR, bar)):
            y = y_of(value)
            painter.fillRect(QRectF(x + offset, y, bar * 0.95, plot.bottom() - y), QColor(colour))
        painter.setPen(QColor("#333333"))
        painter.drawText(QRectF(plot.left() + i * slot, plot.bottom() + 4, slot, 18),
                         Qt.AlignmentFlag.AlignCenter, label)
    painter.setPen(QPen(QColor("#333333"), 1))
    painter.drawRect(plot)
    for k, (text, colour) in enumerate((("before calibration", BEFORE_COLOUR),
                                        ("after", AFTER_COLOUR))):
        x = plot.left() + 10 + k * 170
        painter.fillRect(QRectF(x, 8, 14, 14), QColor(colour))
        painter.drawText(QPointF(x + 20, 20), text)
    painter.drawText(QRectF(0, height - 22, width, 20), Qt.AlignmentFlag.AlignCenter,
                     f"tilt error per pose against {report.tilt_reference or 'the reference'}"
                     " (log scale)")
    painter.end()
    return image


def _nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """Round tick values (1, 2, 5 x 10^n steps) inside [low, high]."""
    span = max(high - low, 1e-12)
    raw = span / count
    step = 10 ** math.floor(math.log10(raw))
    for factor in (1, 2, 5, 10):
        if factor * step >= raw:
            step *= factor
            break
    first = math.ceil(low / step) * step
    return [round(first + i * step, 12) for i in range(int((high - first) / step) + 1)]


def temperature_plot(section: TemperatureSection, width: int = 900,
                     height: int = 360) -> QImage:
    """Bias change against temperature per axis: the bin means (dots) and the fitted curve,
    gyroscope left, accelerometer right."""
    image = QImage(width, height, QImage.Format.Format_ARGB32)
    image.fill(QColor("white"))
    painter = QPainter(image)
    painter.setRenderHint(QPainter.RenderHint.Antialiasing)
    font = QFont()
    font.setPixelSize(12)
    painter.setFont(font)
    t_lo, t_hi = section.temp_min_degc, section.temp_max_degc
    t_lo, t_hi = min(t_lo, section.reference_temp_degc), max(t_hi, section.reference_temp_degc)
    pad = 0.03 * max(t_hi - t_lo, 0.1)
    t_lo, t_hi = t_lo - pad, t_hi + pad
    grid = np.linspace(t_lo, t_hi, 200)
    panel_w = width / 2
    for p, title in enumerate(("Gyroscope", "Accelerometer")):
        if title not in section.points:
            continue
        unit, temps, values = section.points[title]
        k1, k2 = section.curves[title]
        d = (grid - section.reference_temp_degc)[:, None]
        curve = d * k1 + d * d * k2
        finite = np.concatenate([values[np.isfinite(values)], curve.ravel()])
        v_lo, v_hi = float(finite.min()), float(finite.max())
        margin = 0.08 * max(v_hi - v_lo, 1e-9)
        v_lo, v_hi = v_lo - margin, v_hi + margin
        left, right, top, bottom = p * panel_w + 62, 14, 34, 46
        plot = QRectF(left, top, panel_w - 62 - right, height - top - bottom)

        def xy(t: float, v: float, plot=plot, v_lo=v_lo, v_hi=v_hi) -> QPointF:
            return QPointF(plot.left() + (t - t_lo) / (t_hi - t_lo) * plot.width(),
                           plot.bottom() - (v - v_lo) / (v_hi - v_lo) * plot.height())

        painter.setPen(QPen(QColor("#dddddd"), 1))
        for tick in _nice_ticks(v_lo, v_hi):
            y = xy(t_lo, tick).y()
            painter.drawLine(QPointF(plot.left(), y), QPointF(plot.right(), y))
            painter.setPen(QColor("#333333"))
            painter.drawText(QRectF(p * panel_w, y - 8, 58, 16),
                             Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter,
                             f"{tick:+.3g}" if tick else "0")
            painter.setPen(QPen(QColor("#dddddd"), 1))
        for tick in np.linspace(t_lo + pad, t_hi - pad, 5):
            x = xy(tick, v_lo).x()
            painter.setPen(QColor("#333333"))
            painter.drawText(QRectF(x - 30, plot.bottom() + 3, 60, 16),
                             Qt.AlignmentFlag.AlignCenter, f"{tick:.1f}")
        # T0
        painter.setPen(QPen(QColor("#888888"), 1, Qt.PenStyle.DashLine))
        x0 = xy(section.reference_temp_degc, v_lo).x()
        painter.drawLine(QPointF(x0, plot.top()), QPointF(x0, plot.bottom()))
        for axis in range(3):
            colour = QColor(AXIS_COLOURS[axis])
            painter.setPen(Qt.PenStyle.NoPen)
            painter.setBrush(colour)
            for t, v in zip(temps, values[:, axis], strict=True):
                if math.isfinite(v):
                    painter.drawEllipse(xy(float(t), float(v)), 2.6, 2.6)
            painter.setBrush(Qt.BrushStyle.NoBrush)
            painter.setPen(QPen(colour, 2))
            points = [xy(float(t), float(v)) for t, v in zip(grid, curve[:, axis], strict=True)]
            painter.drawPolyline(QPolygonF(points))
        painter.setPen(QPen(QColor("#333333"), 1))
        painter.drawRect(plot)
        model = section.models.get(title, "")
        painter.drawText(QRectF(plot.left(), 6, plot.width(), 18), Qt.AlignmentFlag.AlignCenter,
                         f"{title} bias change ({unit}), {model} fit")
        painter.drawText(QRectF(plot.left(), height - 24, plot.width(), 18),
                         Qt.AlignmentFlag.AlignCenter, "die temperature (°C); dashed: T0")
    for axis, name in enumerate(("x", "y", "z")):
        painter.setPen(QColor(AXIS_COLOURS[axis]))
        painter.drawText(QPointF(10 + axis * 18, height - 8), name)
    painter.end()
    return image


def _png_bytes(image: QImage) -> bytes:
    data = QByteArray()
    buffer = QBuffer(data)
    buffer.open(QIODevice.OpenModeFlag.WriteOnly)
    image.save(buffer, "PNG")
    buffer.close()
    return bytes(data.data())


# -- the document ----------------------------------------------------------------------------------
def _fmt(value: float, spec: str = "+.4f") -> str:
    return format(float(value), spec) if value is not None and math.isfinite(value) else "–"


def _temperature_html(section: TemperatureSection, image_src: str) -> list[str]:
    e = html.escape
    rows = []
    for sensor, name, unit, values, std in section.rows:
        cells = "".join(
            f"<td align='right'>{_fmt(v, '+.5g')}"
            + (f" ± {_fmt(sd, '.2g')}" if std is not None else "") + "</td>"
            for v, sd in zip(values, std if std is not None else [None] * 3, strict=True))
        rows.append(f"<tr><td>{e(sensor)}</td><td>{e(name)}</td><td>{e(unit)}</td>{cells}</tr>")
    models = ", ".join(f"{e(k)} {e(v)}" for k, v in section.models.items())
    parts = [
        "<h2>Temperature compensation</h2>",
        "<p>b(T) = b<sub>0</sub> + k<sub>1</sub> (T − T<sub>0</sub>) + k<sub>2</sub> "
        f"(T − T<sub>0</sub>)², T<sub>0</sub> = {section.reference_temp_degc:.2f} °C; fitted "
        f"on still data from {section.temp_min_degc:.2f} to {section.temp_max_degc:.2f} °C. "
        f"Model: {models} ({e(section.criterion)}).</p>",
        "<table><tr><th>Sensor</th><th>Term</th><th>Unit</th><th>x</th><th>y</th><th>z</th>"
        "</tr>", *rows, "</table>",
    ]
    if section.summary:
        parts.append("<ul>" + "".join(f"<li>{e(line)}</li>" for line in section.summary)
                     + "</ul>")
    parts.append(f"<p><img src='{image_src}' width='640'></p>")
    if section.truth:
        parts.append("<p>Against the simulator's truth:</p><table><tr><th>Coefficient</th>"
                     "<th>Unit</th><th></th><th>x</th><th>y</th><th>z</th></tr>")
        for name, unit, fitted, true in section.truth:
            for what, values in (("fitted", fitted), ("truth", true)):
                cells = "".join(f"<td align='right'>{_fmt(v, '+.4f')}</td>" for v in values)
                parts.append(f"<tr><td>{e(name) if what == 'fitted' else ''}</td>"
                             f"<td>{e(unit) if what == 'fitted' else ''}</td><td>{what}</td>"
                             f"{cells}</tr>")
        parts.append("</table>")
    return parts


def report_html(report: CalibrationReport, image_src: str = PLOT_NAME,
                temperature_src: str = TEMPERATURE_PLOT_NAME) -> str:
    """The report as HTML (Qt's rich-text subset, so the PDF looks the same)."""
    e = html.escape
    s = report.settings
    temperature = (f"{report.temperature_degc:.2f} °C" if math.isfinite(report.temperature_degc)
                   else "unknown")
    rows = []
    for name, unit, values, std in report.parameters:
        cells = "".join(
            f"<td align='right'>{_fmt(v)}" + (f" ± {_fmt(sd, '.4f')}" if std is not None else "")
            + "</td>" for v, sd in zip(values, std if std is not None else [None] * 3,
                                       strict=True))
        rows.append(f"<tr><td>{e(name)}</td><td>{e(unit)}</td>{cells}</tr>")
    poses = "".join(
        f"<tr><td>{i + 1}</td><td>{e(label)}</td><td align='right'>{norm:+.3f}</td>"
        f"<td align='right'>{before:.3f}</td><td align='right'>{after:.4f}</td></tr>"
        for i, (label, norm, before, after) in enumerate(report.poses))
    before_max = max((b for _, _, b, _ in report.poses), default=math.nan)
    after_max = max((a for _, _, _, a in report.poses), default=math.nan)
    parts = [
        "<html><head><meta charset='utf-8'><title>Calibration report</title>",
        "<style>body{font-family:sans-serif;font-size:10pt;color:#000;background-color:#fff}"
        " table{border-collapse:collapse}"
        " td,th{border:1px solid #999;padding:3px 6px;color:#000} th{background:#e8e8e8}"
        " h1{font-size:16pt} h2{font-size:12pt;margin-top:14px}</style></head><body>",
        f"<h1>Calibration report — {e(report.device_id)}</h1>",
        "<table>",
        f"<tr><th align='left'>Device</th><td>{e(report.device_id)} {e(str(s.get('device', '')))}"
        "</td></tr>",
        f"<tr><th align='left'>Date (UTC)</th><td>{e(report.created_utc)}</td></tr>",
        f"<tr><th align='left'>Sensor settings</th><td>{e(str(s.get('sensor', '')))}, "
        f"{float(s.get('odr_hz', math.nan)):.4g} Hz, ±{s.get('accel_fs_g')} g, "
        f"±{s.get('gyro_fs_dps')} °/s</td></tr>",
        f"<tr><th align='left'>Temperature</th><td>{temperature}</td></tr>",
        f"<tr><th align='left'>Method</th><td>{e(report.method)}</td></tr>",
        f"<tr><th align='left'>Source</th><td>{e(report.source)}</td></tr>",
        f"<tr><th align='left'>Program</th><td>inclinometer {e(__version__)}</td></tr>",
        "</table>",
    ]
    if report.parameters:
        parts += [
            "<h2>Fitted parameters (value ± 1σ)</h2>",
            "<p>Model a<sub>meas</sub> = M a<sub>true</sub> + b; the pipeline applies "
            "a<sub>cal</sub> = M<sup>−1</sup> (a<sub>raw</sub> − b).</p>",
            "<table><tr><th>Parameter</th><th>Unit</th><th>x</th><th>y</th><th>z</th></tr>",
            *rows, "</table>",
            f"<p>Residual: {_fmt(report.residual_norm_rms_mg, '.3f')} mg RMS of |a| − 1 g.</p>",
        ]
    if report.poses:
        parts += [
            "<h2>Poses: residuals and tilt error before / after</h2>",
            f"<p>Tilt error against {e(report.tilt_reference)}: worst {before_max:.3f}° "
            f"before, {after_max:.4f}° after.</p>",
            "<table><tr><th>#</th><th>Pose</th><th>|a| − g (mg)</th><th>before (°)</th>"
            "<th>after (°)</th></tr>", poses, "</table>",
            f"<p><img src='{image_src}' width='640'></p>",
        ]
    if report.temperature is not None:
        parts += _temperature_html(report.temperature, temperature_src)
    if report.rejected:
        parts.append("<h2>Rejected capture attempts</h2><ul>"
                     + "".join(f"<li>{e(r)}</li>" for r in report.rejected) + "</ul>")
    if report.truth:
        parts.append("<h2>Against the simulator's truth</h2><table><tr><th>Parameter</th>"
                     "<th>Unit</th><th></th><th>x</th><th>y</th><th>z</th></tr>")
        for name, unit, recovered, true in report.truth:
            for what, values in (("recovered", recovered), ("truth", true),
                                 ("error", np.asarray(recovered) - np.asarray(true))):
                cells = "".join(f"<td align='right'>{_fmt(v)}</td>" for v in values)
                parts.append(f"<tr><td>{e(name) if what == 'recovered' else ''}</td>"
                             f"<td>{e(unit) if what == 'recovered' else ''}</td><td>{what}</td>"
                             f"{cells}</tr>")
        parts.append("</table>")
    if report.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{e(n)}</li>" for n in report.notes)
                     + "</ul>")
    parts.append(report.magnetometer_html)  # magview (#31): the magnetometer's section
    parts.append("</body></html>")
    return "\n".join(parts)


# --- magview (#31): the magnetometer's section (a separate function, ported with the report) ---
def magnetometer_section_html(result, expected=None) -> str:
    """The magnetometer's section: verdict, residual, coverage, field and dip against the
    local WMM value, hard iron, the soft-iron matrix (with the chip's turn against the
    accelerometer) and the reasons for a redo. ``result`` a
    :class:`app.core.magnetometer.fit.MagFitResult`, ``expected`` the WMM
    :class:`app.core.earth_field.EarthField` (or None)."""
    from app.core.magnetometer.fit import alignment_deg

    e = html.escape
    cal = result.calibration
    rows = [
        ("Verdict", "good" if result.good else "redo"),
        ("Fit residual", f"{cal.fitness_ut:.3f} µT RMS of |m| − F"),
        ("Coverage", f"{cal.coverage:.0%} of the sphere's 80 sections"),
        ("Field strength F", f"{cal.field_ut:.2f} µT" + (
            "" if expected is None else f" (local WMM {expected.total_ut:.2f} µT)")),
        ("Dip", f"{cal.dip_deg:+.2f}°" + (
            "" if expected is None else f" (local WMM {expected.dip_deg:+.2f}°)")),
        ("Hard iron", ", ".join(f"{v:+.2f}" for v in cal.hard_iron_ut) + " µT"),
        ("Chip turned against the accelerometer", f"{alignment_deg(cal.soft_iron):.2f}°"),
        ("Samples", f"{result.samples_used} field samples, {result.still_samples} at rest, "
                    f"{result.outliers} dropped as off the sphere"),
    ]
    parts = ["<h2>Magnetometer (m = soft_iron (raw − hard_iron))</h2><table>"]
    parts += [f"<tr><th align='left'>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in rows]
    parts.append("</table><p>Soft-iron matrix (includes the turn into the accelerometer's "
                 "axes):</p><table>")
    for row in cal.soft_iron:
        parts.append("<tr>" + "".join(f"<td align='right'>{v:+.5f}</td>" for v in row)
                     + "</tr>")
    parts.append("</table>")
    if result.reasons:
        parts.append("<p><b>Redo:</b></p><ul>"
                     + "".join(f"<li>{e(r)}</li>" for r in result.reasons) + "</ul>")
    return "\n".join(parts)
# --- end magview ---


def report_document(report: CalibrationReport) -> QTextDocument:
    """The report as a QTextDocument with its plot as a resource (for PDF and screenshots)."""
    document = QTextDocument()
    document.addResource(QTextDocument.ResourceType.ImageResource, QUrl(PLOT_NAME),
                         tilt_plot(report))
    if report.temperature is not None:
        document.addResource(QTextDocument.ResourceType.ImageResource,
                             QUrl(TEMPERATURE_PLOT_NAME), temperature_plot(report.temperature))
    document.setHtml(report_html(report))
    return document


def write_report(report: CalibrationReport, path: Path) -> Path:
    """Write ``path`` as HTML (plot embedded) or PDF (by its suffix)."""
    path = Path(path)
    if path.suffix.lower() == ".pdf":
        writer = QPdfWriter(str(path))
        writer.setPageLayout(QPageLayout(QPageSize(QPageSize.PageSizeId.A4),
                                         QPageLayout.Orientation.Portrait,
                                         QMarginsF(15, 15, 15, 15),
                                         QPageLayout.Unit.Millimeter))
        writer.setTitle(f"Calibration report {report.device_id}")
        writer.setCreator(f"inclinometer {__version__}")
        document = report_document(report)
        document.print_(writer)
        del writer  # finishes the file
        return path
    png = base64.b64encode(_png_bytes(tilt_plot(report))).decode("ascii")
    temperature_src = TEMPERATURE_PLOT_NAME
    if report.temperature is not None:
        data = base64.b64encode(_png_bytes(temperature_plot(report.temperature)))
        temperature_src = f"data:image/png;base64,{data.decode('ascii')}"
    path.write_text(report_html(report, f"data:image/png;base64,{png}", temperature_src),
                    encoding="utf-8")
    return path


def render_preview(report: CalibrationReport, width: int = 820) -> QImage:
    """The document drawn into an image (what the PDF pages hold, for a screenshot)."""
    document = report_document(report)
    document.setTextWidth(width)
    size = document.size()
    image = QImage(int(size.width()), int(size.height()), QImage.Format.Format_ARGB32)
    image.fill(QColor("white"))
    painter = QPainter(image)
    document.drawContents(painter)
    painter.end()
    return image
