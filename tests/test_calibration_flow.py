"""The whole calibration as the wizard will run it, on one simulated stream, into a profile.

One tour (each face held 12 s) feeds the gyro-bias step and the six-position capture side by
side; the results become a profile that is saved, loaded and applied to still poses it never
saw, across +-60 degrees of tilt.
"""

from __future__ import annotations

import numpy as np

from app.core.calibration_procedures import (
    CaptureState,
    GyroBiasCalibration,
    GyroBiasState,
    PoseCapture,
    ProfileStore,
    SensorNoise,
    SensorSettings,
    StillnessDetector,
    compare_tilt,
    fit_six_position,
    make_profile,
)
from app.core.orientation import up_in_sensor_frame
from app.core.samples import convert_raw_block
from drivers.registry import open_device


def test_gyro_and_six_positions_from_one_tour_into_a_profile(tmp_path):
    dev = open_device("sim://tour?hold=12&odr=104&realtime=0&block=256&seed=7&errors=1")
    info = dev.info
    noise = SensorNoise.lsm6dsox(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps)
    capture = PoseCapture(StillnessDetector(noise))
    gyro = GyroBiasCalibration(StillnessDetector(noise))
    while capture.state is not CaptureState.COMPLETE:
        block = convert_raw_block(dev.read(1.0))
        capture.update(block)
        gyro.update(block)
    assert gyro.state is GyroBiasState.DONE  # done on the first face, after 10.5 s
    fit = fit_six_position(capture.poses)
    calibration = fit.to_calibration(gyro.result, name="six-position")
    settings = SensorSettings(info.odr_hz, info.accel_fs_g, info.gyro_fs_dps)
    residuals = {**fit.summary(), "gyro_bias_std_dps": gyro.result.std_error_dps}
    store = ProfileStore(tmp_path)
    store.save(make_profile(info.unique_id, calibration, settings, method="six-position",
                            temperature_degc=fit.temperature_degc, residuals=residuals))

    # Next session: the profile is loaded on connect and applied by the pipeline's stage.
    loaded = store.load_for_device(info.unique_id)
    assert loaded is not None and loaded.settings.differences(settings) == []
    assert loaded.residuals["poses"] == 6
    applied = loaded.calibration
    means, ups = [], []
    for roll, pitch in [(0, 0), (60, 0), (0, -60), (-42, 42), (30, 30), (-20, -55)]:
        still = open_device(
            f"sim://static?roll={roll}&pitch={pitch}&odr=104&realtime=0&block=208&seed=7"
        )
        raw = convert_raw_block(still.read(1.0))
        corrected = applied.apply(raw)
        np.testing.assert_allclose(np.degrees(corrected.gyro_rad_s.mean(axis=0)), 0.0, atol=0.01)
        means.append(raw.accel_m_s2.mean(axis=0))
        ups.append(up_in_sensor_frame(raw.reference_quat[0]))
    comparison = compare_tilt(np.array(means), np.array(ups), applied)
    assert comparison.after.max_deg <= 0.05
    assert comparison.before.max_deg > 0.3
