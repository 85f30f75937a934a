"""The compass in the window: the rose's states, the heading readout, the disturbance light,
the heading in Ctrl+C and the measurement log, and the heading settings round trip."""

from __future__ import annotations

import math
from datetime import date

import numpy as np
import pytest
from PySide6.QtCore import QRect, QSettings
from PySide6.QtGui import QGuiApplication

from app.core.earth_field import Place
from app.core.field_check import ReferenceSettings
from app.core.field_light import CLEAN, DISTURBED, NO_FIELD, FieldLight
from app.core.filters import FILTERS
from app.core.filters.base import MAGNETOMETER_PARAMETER, OrientationFilter
from app.core.heading import (
    NO_HEADING_FILTER,
    NO_MAGNETOMETER,
    OK,
    VERTICAL,
    HeadingReading,
    HeadingSettings,
    averaged_heading,
    signed_difference_deg,
    typed_declination,
    wmm_declination,
)
from app.core.measurement_log import LOG_FILE_NAME
from app.gui import main_window as main_window_module
from app.gui import theme
from app.gui.compass import CompassPanel, CompassRose
from app.gui.main_window import MainWindow
from app.services.session import DeviceSession

TIMEOUT_MS = 15_000


class TruthFilter(OrientationFilter):
    """A stand-in 9-axis filter for these tests: the simulator's true orientation (ENU, y
    magnetic north), which is what a 9-axis filter's output is defined to be."""

    name = "test-truth"
    title = "Simulator truth (test)"
    uses_magnetometer = True
    parameters = (MAGNETOMETER_PARAMETER,)

    def _process(self, block):
        return block.reference_quat


@pytest.mark.parametrize("size", [96, 140, 300])
@pytest.mark.parametrize("state, title", [
    (NO_MAGNETOMETER, "NO MAGNETOMETER"), (NO_HEADING_FILTER, "FILTER WITHOUT MAGNETOMETER"),
    (VERTICAL, "HEADING UNAVAILABLE"), ("no data", "NO DATA")])
def test_the_rose_says_why_there_is_no_heading_and_the_words_fit(qtbot, size, state, title):
    rose = CompassRose()
    qtbot.addWidget(rose)
    rose.resize(size, size)
    rose.setReading(HeadingReading(state, message="why"))
    assert rose.stateTitle() == title and rose.needleAngle() is None
    assert rose.titleFits()
    rose.grab()  # paints without error
    rose.setReading(HeadingReading(OK, 123.4))
    assert rose.stateTitle() == "" and rose.needleAngle() == pytest.approx(123.4)


def test_heading_tile_and_light_show_what_they_are_given(qtbot):
    panel = CompassPanel()
    qtbot.addWidget(panel)
    panel.setReading(HeadingReading(OK, 123.44, "magnetic", "deg"))
    assert panel.tile.readoutText() == "123.4°" and panel.tile.side.text() == "SE"
    panel.setReading(HeadingReading(OK, 123.0, "true", "mil"), "+4.4°")
    assert panel.tile.readoutText() == "2187 mil"
    assert panel.tile.note.text() == "true · decl +4.4°"
    panel.setReading(HeadingReading(NO_MAGNETOMETER, message="no magnetometer"))
    assert panel.tile.readoutText() == "—" and panel.rose.stateTitle() == "NO MAGNETOMETER"
    panel.setLight(FieldLight(DISTURBED, "field 23 % above normal", "WMM"))
    assert panel.light.words() == "Field disturbed: field 23 % above normal"
    assert theme.COLORS["ALARM_RED"] in panel.light.dot.styleSheet()
    panel.setLight(FieldLight(CLEAN, "", "WMM"))
    assert panel.light.words() == "Field normal"
    assert theme.COLORS["OK_GREEN"] in panel.light.dot.styleSheet()
    panel.setLight(FieldLight(NO_FIELD))
    assert panel.light.words() == "No magnetometer"


def open_window(qtbot, tmp_path, url: str) -> MainWindow:
    theme.apply_theme(QGuiApplication.instance(), "dark")
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    window = MainWindow(DeviceSession(), settings, url)
    qtbot.addWidget(window)
    window.show()
    window.fit_to_screen(QRect(0, 0, 1920, 1080))
    qtbot.waitUntil(lambda: window.width() == 1920, timeout=TIMEOUT_MS)
    for dock in window.docks.values():  # the centre gets the width (the offscreen fonts
        dock.hide()                     # make the docks wider than on a desktop)
    qtbot.waitUntil(lambda: window.session.device_info is not None, timeout=TIMEOUT_MS)
    qtbot.waitUntil(window.level_view.compass_column.isVisible, timeout=TIMEOUT_MS)
    return window


@pytest.fixture
def log_path(tmp_path, monkeypatch):
    path = tmp_path / "data" / LOG_FILE_NAME
    monkeypatch.setattr(main_window_module, "default_log_path", lambda: path)
    return path


def test_window_states_without_a_heading(qtbot, tmp_path, log_path):
    window = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2")
    try:
        qtbot.waitUntil(lambda: window.compass.rose.stateTitle() == "NO MAGNETOMETER",
                        timeout=TIMEOUT_MS)
        assert window.compass.light.words() == "No magnetometer"
        window.connect_device("sim://static?odr=104&seed=2&mag=lis3mdl")
        # A filter without the magnetometer: its heading is arbitrary and not shown.
        window.session.requestFilter.emit("complementary")
        qtbot.waitUntil(lambda: window.compass.rose.stateTitle()
                        == "FILTER WITHOUT MAGNETOMETER", timeout=TIMEOUT_MS)
        assert window.compass.tile.readoutText() == "—"
        assert "Heading" not in window.copy_reading()
        # Too narrow for the compass column: it is left out (the window may be as narrow as
        # before it came), and it comes back with the room; the instrument mode leaves it out.
        column = window.level_view.compass_column
        assert column.isVisible()
        window.resize(760, 600)
        qtbot.waitUntil(lambda: not column.isVisible(), timeout=TIMEOUT_MS)
        window.fit_to_screen(QRect(0, 0, 1920, 1080))
        qtbot.waitUntil(column.isVisible, timeout=TIMEOUT_MS)
        window.set_instrument_mode(True)
        qtbot.waitUntil(lambda: not column.isVisible(), timeout=TIMEOUT_MS)
        window.set_instrument_mode(False)
        qtbot.waitUntil(column.isVisible, timeout=TIMEOUT_MS)
    finally:
        window.close()


def test_a_source_with_a_magnetometer_gets_the_9_axis_default_until_the_user_chooses(
        qtbot, tmp_path, log_path):
    from app.core.filters import DEFAULT_FILTER, DEFAULT_FILTER_9AXIS

    window = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2&mag=lis3mdl")
    try:
        qtbot.waitUntil(lambda: window.status_filter.text().endswith(
            FILTERS[DEFAULT_FILTER_9AXIS].title), timeout=TIMEOUT_MS)
        # The filter checks the field it learns against the WMM's at the place the user set
        # in the Field dock (not at the default place: a guess), and follows it.
        pipeline, presenter = window.session.pipeline, window.field_presenter
        assert presenter.reference is not None and pipeline.filter._field_reference is None
        window.field_view.reference_bar.settingsChanged.emit(  # as an edit of the place does
            ReferenceSettings(Place(-33.9, 151.2, 0.0)))  # Sydney
        qtbot.waitUntil(lambda: pipeline.filter._field_reference == presenter.reference,
                        timeout=TIMEOUT_MS)
        assert pipeline.filter._field_reference.dip_deg < 0  # the southern hemisphere's
        window.connect_device("sim://static?odr=104&seed=2")  # no magnetometer
        qtbot.waitUntil(lambda: window.status_filter.text().endswith(
            FILTERS[DEFAULT_FILTER].title), timeout=TIMEOUT_MS)
        window.filter_panel.filterRequested.emit("ekf")  # what picking it in the dock does
        qtbot.waitUntil(lambda: window.status_filter.text().endswith(FILTERS["ekf"].title),
                        timeout=TIMEOUT_MS)
    finally:
        window.close()
    # The choice is the user's now: it holds for the next start, on a source of either kind.
    again = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2&mag=lis3mdl")
    try:
        qtbot.waitUntil(lambda: again.status_filter.text().endswith(FILTERS["ekf"].title),
                        timeout=TIMEOUT_MS)
        box = again.filter_panel.source_default
        assert not box.isChecked()
        box.click()  # "The source's default" again
        qtbot.waitUntil(lambda: again.status_filter.text().endswith(
            FILTERS[DEFAULT_FILTER_9AXIS].title), timeout=TIMEOUT_MS)
        assert box.isChecked()
        assert again.window_settings.filter() is None
    finally:
        again.close()


def test_heading_shown_copied_logged_and_its_settings_kept(qtbot, tmp_path, log_path,
                                                          monkeypatch):
    monkeypatch.setitem(FILTERS, "test-truth", TruthFilter)
    window = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2&mag=lis3mdl&errors=0")
    try:
        window.session.requestFilter.emit("test-truth")
        # The default filter shows a heading too (it takes it from the field): wait for the
        # stand-in, then for a second of its samples so the averaging window holds its alone.
        pipeline = window.session.pipeline
        qtbot.waitUntil(lambda: pipeline.filter.name == "test-truth", timeout=TIMEOUT_MS)
        switched = pipeline.samples.total_written
        qtbot.waitUntil(lambda: pipeline.samples.total_written > switched + 2 * 104,
                        timeout=TIMEOUT_MS)
        qtbot.waitUntil(lambda: window.compass.rose.needleAngle() is not None,
                        timeout=TIMEOUT_MS)
        truth = window.session.pipeline.samples.window(0.5, ["ref_quat"])["ref_quat"]
        expected = averaged_heading(truth)
        assert expected is not None and expected.defined
        shown = window.compass.rose.needleAngle()
        assert abs(signed_difference_deg(shown, expected.heading_deg)) < 1.0
        assert window.compass.tile.readoutText() == f"{shown:.1f}°"
        assert window.compass.light.words() == "Field normal"  # an ideal chip, no magnet

        declination = wmm_declination(Place(48.1, 11.6), date(2026, 6, 1))
        window.hold_button.setChecked(True)  # the figures stop: the log takes the held ones
        window.heading_controls.use(HeadingSettings("true", "mil", declination))
        qtbot.waitUntil(lambda: window.compass.tile.reading().north == "true",
                        timeout=TIMEOUT_MS)
        true_mils = (shown + declination.declination_deg) % 360.0 * 6400.0 / 360.0
        text = window.compass.tile.readoutText()
        assert text.endswith(" mil") and abs(float(text.split()[0]) - true_mils) <= 1.0
        copied = window.copy_reading()
        assert copied.endswith(f"Heading {text} true") and copied.startswith("Roll ")
        assert QGuiApplication.clipboard().text() == copied
        reading = window.presenter.current_reading("north wall")
        assert reading is not None and reading.heading_north == "true"
        assert reading.heading_unit == "mil" and abs(reading.heading - true_mils) <= 1.0
        assert reading.heading_std < 1.0  # at rest: the true orientation hardly moves
        worker = window.session.worker
        qtbot.waitUntil(lambda: worker.acquisition.declination == declination,
                        timeout=TIMEOUT_MS)
    finally:
        window.close()
    again = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2")
    try:
        assert again.heading_controls.settings == HeadingSettings("true", "mil", declination)
        assert again.heading_bar.north_combo.currentData() == "true"
        assert again.heading_bar.unit_combo.currentData() == "mil"
        qtbot.waitUntil(lambda: again.session.worker.acquisition.declination == declination,
                        timeout=TIMEOUT_MS)
    finally:
        again.close()


def test_true_north_asks_for_a_declination_and_stays_magnetic_without_one(qtbot, tmp_path,
                                                                          log_path):
    window = open_window(qtbot, tmp_path, "sim://static?odr=104&seed=2")
    try:
        asked = []
        window.heading_controls.ask = lambda current: asked.append(current)  # cancelled
        bar = window.heading_bar
        bar.north_combo.setCurrentIndex(bar.north_combo.findData("true"))
        assert asked == [None]
        assert window.heading_controls.settings.north == "magnetic"
        assert bar.north_combo.currentData() == "magnetic"
        window.heading_controls.ask = lambda current: typed_declination(-7.5)
        bar.north_combo.setCurrentIndex(bar.north_combo.findData("true"))
        assert window.heading_controls.settings == HeadingSettings(
            "true", "deg", typed_declination(-7.5))
        assert not math.isnan(window.heading_controls.settings.declination.declination_deg)
    finally:
        window.close()


def test_a_magnet_passing_lights_the_field_red_with_its_reason(qtbot):
    """The compass's feed on a pipeline fed block by block from a simulated magnet passing
    (150 uT at its closest, from 0.5 to 4.5 s): normal, then red with by how much, then
    normal again."""
    from types import SimpleNamespace

    from app.core.field_check import wmm_reference
    from app.core.pipeline import Pipeline
    from app.gui.feeds.frame import Frame
    from app.gui.feeds.heading import LIGHT_INTERVAL_S, HeadingFeed
    from drivers.registry import create_device

    panel = CompassPanel()
    qtbot.addWidget(panel)
    panel.show()
    qtbot.waitExposed(panel)
    device = create_device("sim://static?odr=104&seed=2&mag=lis3mdl&errors=0&realtime=0"
                           "&block=26&magdist=magnet:150@0.5-4.5")
    info = device.open()
    pipeline = Pipeline(info.odr_hz)
    reference = wmm_reference()
    feed = HeadingFeed(panel, SimpleNamespace(pipeline=pipeline), lambda: reference)
    seen = []
    try:
        for step in range(24):  # 6 s of device time, a frame after each quarter second
            pipeline.process(device.read(1.0))
            feed.frame(Frame((step + 1) * LIGHT_INTERVAL_S), (step,), lambda: None, False)
            if not seen or seen[-1] != panel.light.words():
                seen.append(panel.light.words())
    finally:
        device.close()
    assert seen[0] == "Field normal" and seen[-1] == "Field normal"
    red = [words for words in seen if words.startswith("Field disturbed: ")]
    assert red and any("above normal" in words for words in red), seen
    assert panel.tile.readoutText() == "—"  # no attitude handed to it: no heading


def test_the_3d_view_draws_the_earth_axes_when_the_heading_is_real(qtbot):
    from app.core.orientation import quaternion_from_roll_pitch
    from app.core.scene3d import Camera, earth_axes_lines, render_list, sensors_scene
    from app.gui.attitude_view import AttitudeView

    q = quaternion_from_roll_pitch(10.0, 5.0, 30.0)
    scene = sensors_scene([q], earth_axes=True)
    lines = earth_axes_lines(scene)
    assert [label for _key, label, _a, _b in lines] == ["E", "N", "Up"]
    for (_key, _label, start, tip), direction in zip(lines, np.eye(3)):
        along = (tip - start) / np.linalg.norm(tip - start)
        np.testing.assert_allclose(along, direction, atol=1e-12)
    items = render_list(scene, Camera(), 400, 300)
    labels = [item.text for item in items if item.kind == "label"]
    assert labels == ["E", "N", "Up"]
    assert not any(item.color.startswith("earth")
                   for item in render_list(sensors_scene([q]), Camera(), 400, 300))
    view = AttitudeView(backend="painter")
    qtbot.addWidget(view)
    view.show()
    view.set_attitude(q)
    assert not view.canvas.scene.earth_axes
    view.set_earth_frame(True)
    assert view.canvas.scene.earth_axes and view.earth_frame()
    view.canvas.grab()  # paints the axes and their legend without error
