"""The magnetic field's views: the presenter feeds the plots from the pipeline's field ring,
draws the reference, marks a disturbance, and says when a source has a field."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from app.core.earth_field import DEFAULT_PLACE, earth_field
from app.core.field_check import ReferenceSettings
from app.core.pipeline import Pipeline
from app.core.samples import STANDARD_GRAVITY_M_S2, RawBlock, ScaleFactors

G = STANDARD_GRAVITY_M_S2
SCALE = ScaleFactors(0.122e-3 * G, math.radians(8.75e-3), 1 / 256, 25.0, mag_ut_per_lsb=0.1)
WHEN = 2026.5
EARTH = earth_field(DEFAULT_PLACE, WHEN)


def block(start: int, count: int, odr: float = 104.0, field: bool = True,
          extra_ut: float = 0.0) -> RawBlock:
    """A level sensor at rest; a field sample on every 4th row (``extra_ut`` added to x)."""
    rows = start + np.arange(count)
    mag = None
    if field:
        mag = np.full((count, 3), np.nan)
        mag[rows % 4 == 0] = np.round((EARTH.enu_magnetic_ut() + np.array([extra_ut, 0, 0])) / 0.1)
    up = np.round(np.array([0, 0, G]) / SCALE.accel_m_s2_per_lsb)
    return RawBlock(rows / odr, np.tile(up, (count, 1)).astype(np.int16),
                    np.zeros((count, 3), np.int16), np.zeros(count, np.int16), SCALE,
                    mag_raw=mag)


@pytest.fixture
def field(qtbot, host):
    from app.gui.field_view import FieldPresenter, FieldView

    pipeline = Pipeline(odr_hz=104.0)
    session = SimpleNamespace(pipeline=pipeline, device_info=None)
    view = FieldView()
    host.layout().addWidget(view)
    view.setMinimumHeight(360)
    host.show()
    qtbot.waitExposed(host)
    presenter = FieldPresenter(session, view, parent=host)
    presenter.apply_settings(ReferenceSettings(when=None).to_dict() | {"date": "2026-07-02"})
    seen = []
    presenter.availabilityChanged.connect(seen.append)
    problems = []
    presenter.problem.connect(problems.append)
    return SimpleNamespace(pipeline=pipeline, view=view, presenter=presenter, seen=seen,
                           problems=problems)


def feed(pipeline: Pipeline, start: int, count: int, **kwargs) -> int:
    for first in range(start, start + count, 52):
        pipeline.process(block(first, min(52, start + count - first), **kwargs))
    return start + count


def refresh(presenter) -> bool:
    presenter._last = -np.inf  # each call takes what is new (the 10 Hz pacing is not tested)
    return presenter.refresh()


def test_plots_show_the_field_and_the_wmm_reference(field):
    feed(field.pipeline, 0, 520)
    assert refresh(field.presenter)
    assert field.seen == [True]
    plots = field.view.plots
    x, y = plots.mag_curves[1].getData()
    assert len(x) == 130 and x[-1] == 0.0
    np.testing.assert_allclose(y, EARTH.enu_magnetic_ut()[1], atol=0.06)
    _, norm = plots.norm_curve.getData()
    np.testing.assert_allclose(norm, EARTH.total_ut, atol=0.1)
    reference_line = plots.reference_lines[plots.norm_plot][0]
    assert reference_line.isVisible()
    assert reference_line.value() == pytest.approx(EARTH.total_ut, abs=0.01)
    assert plots.reference_lines[plots.dip_plot][0].value() == pytest.approx(EARTH.dip_deg,
                                                                             abs=0.01)
    low, high = plots.ranges[plots.norm_plot].range
    assert low < EARTH.total_ut < high
    assert "matches WMM" in plots.status.text()
    assert len(plots.disturbed_marks.getData()[0]) == 0
    assert not refresh(field.presenter)  # nothing new: nothing drawn


def test_a_magnet_is_marked_and_named_in_the_status_line(field):
    start = feed(field.pipeline, 0, 208)
    feed(field.pipeline, start, 208, extra_ut=30.0)
    assert refresh(field.presenter)
    plots = field.view.plots
    marked_x, marked_y = plots.disturbed_marks.getData()
    assert len(marked_x) == 52  # every field sample of the magnet's 2 s
    assert np.all(marked_y > EARTH.total_ut + 5)
    assert "DISTURBED" in plots.status.text() and "µT" in plots.status.text()


def test_learning_at_rest_replaces_the_reference_and_refuses_motion(field):
    start = feed(field.pipeline, 0, 312, extra_ut=25.0)  # a steel desk: off the WMM value
    assert refresh(field.presenter)
    assert "DISTURBED" in field.view.plots.status.text()
    assert field.presenter.learn_reference()
    assert field.presenter.reference.source.startswith("learnt at rest")
    assert refresh(field.presenter)
    assert "DISTURBED" not in field.view.plots.status.text()
    assert field.presenter.reference.total_ut != pytest.approx(EARTH.total_ut, abs=1.0)
    # A field that changes while learning is refused, with a message; nothing changes.
    for k in range(10):
        start = feed(field.pipeline, start, 26, extra_ut=25.0 + 3 * k)
    before = field.presenter.reference
    assert not field.presenter.learn_reference()
    assert field.presenter.reference is before
    assert "moved" in field.problems[-1]
    field.presenter.use_wmm()
    assert field.presenter.reference.source.startswith("WMM")


def test_view_stays_empty_and_hidden_for_a_source_without_a_field(field):
    feed(field.pipeline, 0, 208, field=False)
    assert not refresh(field.presenter)
    assert field.seen == [False]
    x = field.view.plots.mag_curves[0].getData()[0]
    assert x is None or len(x) == 0
    # Another device with a field: it appears; a reconfigured pipeline: it goes again.
    feed(field.pipeline, 208, 104)
    refresh(field.presenter)
    field.pipeline.configure(104.0)
    refresh(field.presenter)
    assert field.seen == [False, True, False]


def test_reference_bar_reports_a_date_outside_the_model(field, qtbot):
    bar = field.view.reference_bar
    bar.today.setChecked(False)
    from PySide6.QtCore import QDate

    bar.date.setDate(QDate(2035, 1, 1))
    bar.date.editingFinished.emit()
    assert "outside" in field.problems[-1]
    bar.latitude.setValue(-33.9)
    bar.longitude.setValue(151.2)
    bar.today.setChecked(True)
    assert field.presenter.settings.place.latitude_deg == pytest.approx(-33.9)
    assert field.presenter.reference.dip_deg < 0
    assert field.presenter.settings_dict()["latitude_deg"] == pytest.approx(-33.9)
