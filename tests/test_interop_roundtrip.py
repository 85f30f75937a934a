"""Issue 34 item 5: a recording exported to EuRoC and imported again gives the same samples,
through the two commands a user runs (`export --format euroc`, then `import`)."""

from __future__ import annotations

import numpy as np

from app.cli import main
from app.core.recording.reader import read_recording


def test_a_recording_exported_to_euroc_and_imported_again_gives_the_same_samples(tmp_path):
    rec = tmp_path / "wobble.csv"
    assert main(["record", "--device", "sim://wobble?odr=104&seed=2&realtime=0",
                 "--duration", "2s", str(rec)]) == 0
    assert main(["export", str(rec), "--format", "euroc", str(tmp_path / "imu0.csv"),
                 "--raw"]) == 0
    assert main(["import", str(tmp_path / "imu0.csv"), str(tmp_path / "back.csv")]) == 0
    original, back = read_recording(rec), read_recording(tmp_path / "back.csv")
    t0 = back.metadata["imported_from"]["time_origin"]["value"]
    np.testing.assert_array_equal(t0 + np.round(back.t_s * 1e9).astype(np.int64),
                                  np.round(original.t_s * 1e9).astype(np.int64))
    np.testing.assert_array_equal(back.gyro_rad_s, original.gyro_rad_s)
    np.testing.assert_array_equal(back.accel_m_s2, original.accel_m_s2)
