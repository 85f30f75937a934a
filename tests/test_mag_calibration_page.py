"""The calibration wizard's magnetometer page, fed from the simulated magnetometer's tour: the
coverage fills in, the fit's verdict is shown, a good fit goes into the profile and the
pipeline, a disturbed tour is sent back with its reason."""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pytest
from PySide6.QtCore import QSettings
from PySide6.QtGui import QColor

from app.core.calibration_procedures import ProfileStore
from app.core.magnetometer.fit import alignment_deg
from app.core.pipeline import Pipeline
from app.core.raw_feed import RawSampleFeed
from app.gui import theme
from app.gui.mag_calibration_page import MagnetometerPage, SphereCoverage
from drivers.registry import open_device
from drivers.sim.device import SimulatedDevice

TOUR = "sim://magtour?seed=5&realtime=0"


def run_tour(page: MagnetometerPage, pipeline: Pipeline, url: str, seconds: float,
             on_the_way=None) -> None:
    """Stream ``seconds`` of ``url`` through the pipeline, feeding the page as the wizard's
    timer does (every ~0.1 s of data)."""
    device = open_device(url)
    feed = RawSampleFeed(pipeline)
    try:
        t = 0.0
        while t < seconds:
            raw = device.read(0.1)
            pipeline.process(raw)
            block = feed.next_block()
            if block is not None:
                page.feed(block)
                t = float(block.t_s[-1])
                if on_the_way is not None:
                    on_the_way(t)
    finally:
        device.close()


@pytest.fixture
def page(qtbot):
    pipeline = Pipeline(odr_hz=107.0)
    session = SimpleNamespace(pipeline=pipeline, device_info=None)
    page = MagnetometerPage(session)
    qtbot.addWidget(page)
    page.resize(700, 560)
    page.show()
    qtbot.waitExposed(page)
    return SimpleNamespace(page=page, pipeline=pipeline)


def test_coverage_fills_in_and_a_full_tour_is_good(page, artifacts_dir):
    seen = []
    run_tour(page.page, page.pipeline, TOUR, 95.0,
             lambda t: seen.append(page.page.tracker.fraction))
    fractions = np.array(seen)
    assert np.all(np.diff(fractions) >= 0)  # sections only ever fill in
    # a quarter of the way round, much of the sphere is still to come; at the end the most
    early = fractions[len(fractions) // 10]
    assert early < 0.5 < 0.75 < fractions[-1], (early, fractions[-1])
    assert fractions[len(fractions) // 4] < fractions[-1] - 0.1
    assert page.page.sphere.mask.sum() == round(80 * fractions[-1])
    assert page.page.fit_button.isEnabled()
    result = page.page.run_fit()
    assert result is not None and result.verdict == "good", result.reasons
    assert page.page.isComplete()
    assert page.page.verdict.isVisible()
    assert page.page.verdict.headline.text().startswith("Good")
    assert "µT RMS" in page.page.verdict.details.text()
    # Against the simulated unit's truth (same seed, same unit).
    truth = SimulatedDevice(TOUR).unit_errors.magnetometer
    cal = page.page.calibration
    assert np.max(np.abs(cal.hard_iron_ut - truth.hard_iron_ut)) < 1.0
    # The page fits against the accelerometer as it reads before its own calibration, whose
    # cross-axis errors (a few tenths of a degree on a simulated unit) turn its frame too.
    assert abs(alignment_deg(cal.soft_iron) - truth.alignment_deg) < 0.8
    page.page.grab().save(os.path.join(artifacts_dir, "mag_page_good.png"))
    # The report's magnetometer section says the same.
    from app.documents.calibration_report import magnetometer_section_html

    section = magnetometer_section_html(result, page.page.expected)
    assert "<h2>Magnetometer" in section and "good" in section
    assert f"{cal.fitness_ut:.3f} µT RMS" in section
    assert f"local WMM {page.page.expected.total_ut:.2f} µT" in section


def test_a_magnet_during_the_tour_is_a_redo_with_its_reason(page):
    run_tour(page.page, page.pipeline, TOUR + "&magdist=magnet:80@30", 95.0)
    result = page.page.run_fit()
    assert result is not None and result.verdict == "redo"
    assert any("disturbance" in reason for reason in result.reasons)
    assert page.page.verdict.headline.text().startswith("Redo")
    assert "disturbance" in page.page.verdict.details.text()
    assert not page.page.isComplete() and page.page.calibration is None
    from app.documents.calibration_report import magnetometer_section_html

    assert "<b>Redo:</b>" in magnetometer_section_html(result)
    page.page.skip.setChecked(True)  # the user may leave the magnetometer as it is
    assert page.page.isComplete() and page.page.calibration is None
    page.page.restart()
    assert page.page.tracker.rows == 0 and not page.page.verdict.isVisible()


def test_fit_is_offered_only_once_some_of_the_sphere_is_covered(page):
    assert not page.page.fit_button.isEnabled()
    run_tour(page.page, page.pipeline, TOUR, 3.0)
    assert page.page.tracker.fraction < 0.25
    assert not page.page.fit_button.isEnabled()
    assert "of 80 sections" in page.page.progress.text()


def test_sphere_widget_fills_the_covered_sections(qtbot):
    sphere = SphereCoverage()
    qtbot.addWidget(sphere)
    sphere.resize(400, 220)

    def accent_pixels() -> int:
        image = sphere.grab().toImage()
        accent = QColor(theme.ACCENT).rgb()
        return sum(image.pixel(x, y) == accent for x in range(0, 400, 2)
                   for y in range(0, 220, 2))

    empty = accent_pixels()
    half = np.zeros(80, bool)
    half[::2] = True
    sphere.set_mask(half)
    some = accent_pixels()
    sphere.set_mask(np.ones(80, bool))
    full = accent_pixels()
    assert empty == 0 < some < full
    assert 0.3 < some / full < 0.7


def test_wizard_runs_the_magnetometer_tour_into_the_profile(qtbot, qapp, tmp_path,
                                                            artifacts_dir):
    from app.gui.main_window import MainWindow
    from app.services.session import DeviceSession

    theme.apply_theme(qapp)
    store = ProfileStore(tmp_path / "profiles")
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    session = DeviceSession(profile_store=store)
    window = MainWindow(session, settings, "sim://magtour?seed=5&speed=25")
    qtbot.addWidget(window)
    window.resize(1280, 860)
    window.show()
    wizard = None
    try:
        qtbot.waitUntil(lambda: session.device_info is not None, timeout=60_000)
        wizard = window.open_calibration_wizard()
        assert wizard.intro.mag_box.isVisible() and wizard.intro.mag_box.isChecked()
        assert wizard.intro.mag_only_button.isVisible()
        before = session.pipeline.calibration
        wizard.intro.mag_only_button.setChecked(True)  # the tour never rests for a gyro step
        wizard.next()
        assert wizard.currentPage() is wizard.mag_page
        mag = wizard.mag_page
        qtbot.waitUntil(lambda: mag.tracker.fraction > 0.2, timeout=60_000)
        wizard.grab().save(os.path.join(artifacts_dir, "wizard_mag_midtour.png"))
        # A whole round of the tour (92 s of field samples at 80 Hz), 25 times faster.
        qtbot.waitUntil(lambda: mag.tracker.rows > 80 * 95, timeout=120_000)
        assert mag.tracker.fraction > 0.75
        result = mag.run_fit()
        assert result is not None and result.good, result and result.reasons
        wizard.grab().save(os.path.join(artifacts_dir, "wizard_mag_verdict.png"))
        wizard.next()
        assert "Magnetometer: residual" in wizard.results_page.summary.text()
        assert "stays as it is" in wizard.results_page.summary.text()
        with qtbot.waitSignal(session.calibrationChanged, timeout=60_000) as blocker:
            wizard.accept()
        profile = blocker.args[0]
        assert profile.calibration.magnetometer is not None
        stored = store.load_for_device(session.device_info.unique_id)
        assert stored.calibration.magnetometer is not None
        qtbot.waitUntil(lambda: session.pipeline.calibration.magnetometer is not None,
                        timeout=60_000)
        # The rest of the calibration in use stays.
        np.testing.assert_array_equal(session.pipeline.calibration.accel_bias_m_s2,
                                      before.accel_bias_m_s2)
    finally:
        if wizard is not None:
            wizard.timer.stop()
        window.close()
