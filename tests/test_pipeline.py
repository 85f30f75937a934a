"""The pipeline converts, calibrates, filters and buffers every block."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.calibration import SensorCalibration
from app.core.orientation import quaternion_from_roll_pitch, up_in_sensor_frame
from app.core.pipeline import Pipeline, capacity_for
from app.core.samples import RawBlock, ScaleFactors, convert_raw_block

G = 9.80665
ACCEL_LSB = 0.122e-3 * G  # +-4 g
GYRO_LSB = np.radians(8.75e-3)  # +-250 dps
SCALE = ScaleFactors(ACCEL_LSB, GYRO_LSB, 1 / 256, 25.0)


def raw_block(start: int, count: int, roll: float = 3.0, pitch: float = -2.0, odr=104.0):
    q = quaternion_from_roll_pitch(roll, pitch)
    accel_lsb = np.round(up_in_sensor_frame(q) * G / ACCEL_LSB).astype(np.int16)
    return RawBlock(
        t_s=(start + np.arange(count)) / odr,
        accel_raw=np.tile(accel_lsb, (count, 1)),
        gyro_raw=np.zeros((count, 3), np.int16),
        temp_raw=np.full(count, 256, np.int16),
        scale=SCALE,
        reference_quat=np.tile(q, (count, 1)),
    )


def test_unit_conversion_uses_the_scale_factors():
    raw = raw_block(0, 4)
    block = convert_raw_block(raw)
    np.testing.assert_allclose(block.accel_m_s2, raw.accel_raw * ACCEL_LSB)
    np.testing.assert_allclose(block.temp_degc, 26.0)
    assert block.gap.dtype == bool and not block.gap.any()


def test_pipeline_fills_the_buffers_with_samples_and_orientation():
    pipeline = Pipeline(odr_hz=104.0)
    for start in range(0, 1040, 52):
        pipeline.process(raw_block(start, 52))
    assert pipeline.counters.samples == 1040
    window = pipeline.orientation.window(1.0)
    assert len(window["t"]) == 105  # 1 s at 104 Hz, both ends included
    assert window["roll"][-1] == pytest.approx(3.0, abs=0.01)
    assert window["pitch"][-1] == pytest.approx(-2.0, abs=0.01)
    assert window["ref_roll"][-1] == pytest.approx(3.0, abs=1e-9)
    assert window["incl_error"][-1] < 0.01
    samples = pipeline.samples.latest(1)
    np.testing.assert_allclose(samples["temp"], [26.0])


def test_calibration_is_applied_before_the_filter():
    pipeline = Pipeline(odr_hz=104.0)
    # A calibration that removes a fake +x bias equal to 1 degree of pitch.
    bias = np.array([np.sin(np.radians(1.0)) * G, 0.0, 0.0])
    pipeline.set_calibration(SensorCalibration(accel_bias_m_s2=bias, name="test"))
    pipeline.process(raw_block(0, 400, roll=0.0, pitch=0.0))
    pitch = pipeline.orientation.latest(1)["pitch"][0]
    assert pitch == pytest.approx(-1.0, abs=0.02)


def test_switching_filters_mid_stream_keeps_the_orientation_continuous():
    pipeline = Pipeline(odr_hz=104.0, filter_name="complementary")
    pipeline.process(raw_block(0, 500, roll=10.0))
    before = pipeline.orientation.latest(1)["roll"][0]
    pipeline.set_filter("accel")
    pipeline.process(raw_block(500, 1, roll=10.0))
    after = pipeline.orientation.latest(1)["roll"][0]
    assert after == pytest.approx(before, abs=0.05)
    assert pipeline.filter.name == "accel"


def test_no_reference_gives_nan_reference_columns():
    pipeline = Pipeline()
    raw = raw_block(0, 10)
    raw.reference_quat = None
    pipeline.process(raw)
    assert np.isnan(pipeline.orientation.latest(1)["incl_error"][0])


def test_lost_samples_and_gaps_are_counted():
    pipeline = Pipeline()
    pipeline.process(raw_block(0, 10))
    raw = raw_block(30, 10)
    raw.lost_samples = 20
    raw.gap = np.zeros(10, bool)
    raw.gap[0] = True
    pipeline.process(raw)
    assert pipeline.counters.lost_samples == 20
    assert pipeline.counters.gaps == 1
    assert pipeline.samples.latest(11)["gap"][1] == 1.0


def test_buffers_are_sized_for_the_longest_window():
    assert capacity_for(6667.0) >= 6667 * 60
    pipeline = Pipeline(odr_hz=6667.0)
    assert pipeline.samples.capacity == capacity_for(6667.0)


def test_comparison_filters_run_side_by_side_with_their_own_buffers():
    pipeline = Pipeline(odr_hz=104.0, filter_name="complementary")
    pipeline.process(raw_block(0, 100, roll=4.0))
    running = pipeline.set_comparisons(["accel", "accel"])
    assert running == ["accel"]
    pipeline.process(raw_block(100, 100, roll=4.0))
    buffer = pipeline.comparison_buffers["accel"]
    assert len(buffer) == 100  # it started when it was added
    latest = buffer.latest(1)
    assert latest["roll"][0] == pytest.approx(4.0, abs=0.01)
    assert latest["incl_error"][0] < 0.01
    # Keeping a comparison keeps its state and buffer; dropping it frees both.
    pipeline.set_comparisons(["accel"])
    assert pipeline.comparison_buffers["accel"] is buffer
    pipeline.set_comparisons([])
    assert pipeline.comparison_buffers == {}
    with pytest.raises(KeyError):
        pipeline.set_comparisons(["nonsense"])


def test_tare_shows_angles_relative_to_the_tared_attitude_and_keeps_raw_columns():
    from app.core.calibration_procedures import TareReference

    pipeline = Pipeline(odr_hz=104.0)
    pipeline.process(raw_block(0, 300, roll=20.0, pitch=10.0))
    pipeline.set_level_reference(TareReference.from_angles(20.0, 10.0))
    pipeline.process(raw_block(300, 100, roll=20.0, pitch=10.0))
    latest = pipeline.orientation.latest(1)
    assert latest["roll"][0] == pytest.approx(0.0, abs=0.02)
    assert latest["pitch"][0] == pytest.approx(0.0, abs=0.02)
    # The error against the absolute reference is unaffected by the tare.
    assert latest["incl_error"][0] < 0.02
    pipeline.set_level_reference(None)
    pipeline.process(raw_block(400, 10, roll=20.0, pitch=10.0))
    assert pipeline.orientation.latest(1)["roll"][0] == pytest.approx(20.0, abs=0.02)
    raw = raw_block(400, 1, roll=20.0, pitch=10.0)
    np.testing.assert_allclose(
        pipeline.samples.latest(1)["raw_accel"][0], raw.accel_raw[0] * ACCEL_LSB
    )


def test_the_filter_follows_the_source_until_one_is_chosen():
    from app.core.filters import DEFAULT_FILTER, DEFAULT_FILTER_9AXIS

    pipeline = Pipeline(104.0)
    assert pipeline.follows_source and pipeline.filter.name == DEFAULT_FILTER
    assert pipeline.adopt_source(has_magnetometer=True)  # a source with a magnetometer
    assert pipeline.filter.name == DEFAULT_FILTER_9AXIS and pipeline.follows_source
    assert pipeline.adopt_source(has_magnetometer=False)
    assert pipeline.filter.name == DEFAULT_FILTER
    pipeline.set_filter("complementary")  # the user's choice holds for every source
    assert not pipeline.follows_source
    assert not pipeline.adopt_source(has_magnetometer=True)
    assert pipeline.filter.name == "complementary"
    assert pipeline.follow_source(has_magnetometer=True)  # and back to the source's
    assert pipeline.filter.name == DEFAULT_FILTER_9AXIS
    chosen = Pipeline(104.0, "ekf")
    assert not chosen.follows_source and not chosen.adopt_source(has_magnetometer=True)


def test_the_wmm_field_reaches_every_filter_now_and_later():
    from app.core.field_check import wmm_reference

    pipeline = Pipeline(104.0, "ekf")
    reference = wmm_reference()
    pipeline.set_field_reference(reference)
    assert pipeline.filter._field_reference is reference
    pipeline.set_comparisons(["vqf-heading", "complementary"])
    assert pipeline.comparisons["vqf-heading"]._field_reference is reference
    pipeline.set_filter("vqf-heading")  # a filter made after the reference was given
    assert pipeline.filter._field_reference is reference
    pipeline.set_field_reference(None)
    assert pipeline.filter._field_reference is None
    assert pipeline.comparisons["vqf-heading"]._field_reference is None
