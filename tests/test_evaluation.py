"""Filter evaluation: scores on errors known by construction, streams, `inclinometer evaluate`."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from app.cli import main
from app.core import evaluation
from app.core.filters import FILTERS
from app.core.filters.base import OrientationFilter
from app.core.orientation import quaternion_from_roll_pitch
from app.core.samples import STANDARD_GRAVITY_M_S2, SampleBlock
from app.services import simulation

ODR = 100.0


def level_stream(seconds: float = 10.0, yaw_deg: float = 30.0) -> SampleBlock:
    """A sensor lying level (reference heading ``yaw_deg``, which scores must ignore)."""
    n = round(seconds * ODR)
    t = np.arange(n) / ODR
    accel = np.tile([0.0, 0.0, STANDARD_GRAVITY_M_S2], (n, 1))
    ref = np.tile(quaternion_from_roll_pitch(0.0, 0.0, yaw_deg), (n, 1))
    return SampleBlock(t, accel, np.zeros((n, 3)), np.full(n, 25.0), np.zeros(n, bool), ref)


class KnownError(OrientationFilter):
    """Answers 'level' with a roll error that is a function of time (``error_deg``)."""

    name = "known"
    title = "Known error"

    @staticmethod
    def error_deg(t: np.ndarray) -> np.ndarray:
        return np.select([t < 2.0, t < 6.0], [50.0, 1.0], default=3.0)

    def _process(self, block: SampleBlock) -> np.ndarray:
        return quaternion_from_roll_pitch(self.error_deg(block.t_s), 0.0)


class Growing(KnownError):
    name = "growing"

    @staticmethod
    def error_deg(t: np.ndarray) -> np.ndarray:
        return 6.0 * t  # runs away: 60 degrees after 10 s


class Constant(KnownError):
    name = "constant"

    @staticmethod
    def error_deg(t: np.ndarray) -> np.ndarray:
        return np.full_like(t, 20.0)  # bad but steady: not a divergence


class SometimesNaN(KnownError):
    name = "nan"

    def _process(self, block: SampleBlock) -> np.ndarray:
        q = quaternion_from_roll_pitch(np.full(len(block), 2.0), 0.0)
        q[(block.t_s >= 5.0) & (block.t_s < 5.5)] = np.nan
        return q


class Broken(KnownError):
    name = "broken"

    def _process(self, block: SampleBlock) -> np.ndarray:
        raise RuntimeError("kaput")


@pytest.mark.parametrize("block", [evaluation.DEFAULT_BLOCK, 7])
def test_rmse_and_max_of_a_known_error_after_the_convergence_time(block):
    (score,) = evaluation.evaluate(level_stream(), [KnownError], block=block)
    # 400 samples at 1 degree (2 <= t < 6), 400 at 3 degrees; the 50 degrees before 2 s skipped.
    assert score.rmse_deg == pytest.approx(math.sqrt((400 * 1 + 400 * 9) / 800), rel=1e-9)
    assert score.max_deg == pytest.approx(3.0, rel=1e-9)
    assert score.scored_samples == 800
    assert score.samples == 1000
    assert score.flag == "ok"
    assert score.samples_per_s > 0


def test_the_skipped_time_is_a_parameter():
    (score,) = evaluation.evaluate(level_stream(), [KnownError], skip_s=0.0)
    assert score.max_deg == pytest.approx(50.0)
    assert score.scored_samples == 1000


def test_flags_nan_divergence_and_errors_and_goes_on():
    scores = evaluation.evaluate(level_stream(), [Growing, Constant, SometimesNaN, Broken])
    by_name = {s.name: s for s in scores}
    assert by_name["growing"].flag == "diverged"
    assert by_name["constant"].flag == "ok"
    assert by_name["constant"].rmse_deg == pytest.approx(20.0)
    nan = by_name["nan"]
    assert nan.flag == "NaN"
    assert nan.nan_samples == 50
    assert nan.rmse_deg == pytest.approx(2.0)  # over the finite estimates
    assert by_name["broken"].flag == "error"
    assert "kaput" in by_name["broken"].message


def test_registered_filters_are_evaluated_by_default():
    scores = evaluation.evaluate(evaluation.split_block(level_stream(4.0), 100))
    assert [s.name for s in scores] == list(FILTERS)
    assert all(s.samples == 400 for s in scores)


def test_a_stream_without_reference_is_refused():
    stream = level_stream(1.0)
    stream.reference_quat = None
    with pytest.raises(ValueError, match="no reference"):
        evaluation.evaluate(stream, ["complementary"])


def test_calibration_from_unit_errors_undoes_the_static_errors():
    from drivers.sim.error_model import UnitErrors

    unit = UnitErrors.draw(5)
    truth = np.random.default_rng(0).normal(size=(20, 3))
    measured_accel = truth @ unit.accel_matrix.T + unit.accel_bias_m_s2
    measured_gyro = truth @ unit.gyro_matrix.T + unit.gyro_bias_rad_s
    n = len(truth)
    block = SampleBlock(np.arange(n) * 0.01, measured_accel, measured_gyro, np.full(n, 25.0),
                        np.zeros(n, bool))
    calibrated = evaluation.calibration_from_unit_errors(unit).apply(block)
    np.testing.assert_allclose(calibrated.accel_m_s2, truth, atol=1e-12)
    np.testing.assert_allclose(calibrated.gyro_rad_s, truth, atol=1e-12)


def test_simulator_stream_compensated_or_raw():
    from drivers.sim.device import SimulatedDevice

    url = "sim://static?odr=104&seed=4"
    unit = SimulatedDevice(url).unit_errors
    compensated = evaluation.concatenate_blocks(simulation.simulator_blocks(url, 3.0))
    raw = evaluation.concatenate_blocks(
        simulation.simulator_blocks(url, 3.0, compensate=False)
    )
    assert len(compensated) == len(raw)
    assert compensated.reference_quat is not None
    gravity = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    raw_gravity = unit.accel_matrix @ gravity + unit.accel_bias_m_s2
    assert np.linalg.norm(raw_gravity - gravity) > 0.3  # this unit's static error (35 mg)
    # Left after compensation: temperature drift, random walk and noise (about 1 mg here).
    tolerance = 0.02
    assert np.linalg.norm(compensated.accel_m_s2.mean(axis=0) - gravity) < tolerance
    assert np.linalg.norm(raw.accel_m_s2.mean(axis=0) - raw_gravity) < tolerance
    assert np.linalg.norm(compensated.gyro_rad_s.mean(axis=0)) < np.radians(0.1)
    assert np.linalg.norm(raw.gyro_rad_s.mean(axis=0) - unit.gyro_bias_rad_s) < np.radians(0.1)


def test_simulator_stream_has_the_asked_length():
    stream = evaluation.concatenate_blocks(
        simulation.simulator_blocks("sim://wobble?odr=52", 5.0, block=64)
    )
    summary = evaluation.stream_summary(stream)
    assert summary["duration_s"] == pytest.approx(5.0, abs=2.0 / summary["rate_hz"])
    assert summary["gaps"] == 0


def test_with_gap_loses_samples_and_marks_the_next():
    stream = level_stream(10.0)
    gapped = evaluation.with_gap(stream, 4.0, 1.5)
    assert len(gapped) == len(stream) - 150
    first_after = np.flatnonzero(gapped.t_s >= 5.5)[0]
    assert np.flatnonzero(gapped.gap).tolist() == [first_after]
    assert not np.any((gapped.t_s >= 4.0) & (gapped.t_s < 5.5))


def test_standard_sources_cover_the_scenarios_and_the_hard_cases():
    sources = simulation.standard_sources(10.0)
    labels = " ".join(s.label for s in sources)
    for name in ("static", "slow-tilt", "wobble", "vibration", "translation", "tour"):
        assert f"sim://{name}?" in labels
    descriptions = [s.description for s in sources]
    assert "an hour at rest" in descriptions
    assert any("90 degrees of pitch" in d for d in descriptions)
    assert any("upside down" in d for d in descriptions)
    gap_source = next(s for s in sources if "lost" in s.description)
    stream = evaluation.concatenate_blocks(gap_source.blocks())
    assert evaluation.stream_summary(stream)["gaps"] == 1


def test_cli_evaluate_prints_a_table(capsys):
    code = main(["evaluate", "sim://wobble?odr=104&seed=4", "--seconds", "5",
                 "--filter", "complementary", "accel"])
    assert code == 0
    out = capsys.readouterr().out
    assert "sim://wobble?odr=104&seed=4" in out
    assert "static errors compensated" in out
    header = next(line for line in out.splitlines() if "RMSE" in line)
    assert header.split() == ["filter", "RMSE", "deg", "max", "deg", "samples/s", "flag"]
    rows = {line.split()[0]: line.split() for line in out.splitlines()
            if line.split() and line.split()[0] in FILTERS}
    assert set(rows) == {"complementary", "accel"}
    for row in rows.values():
        rmse, largest = float(row[1]), float(row[2])
        assert 0.0 < rmse <= largest < 90.0
        assert row[-1] == "ok"


def test_cli_evaluate_refuses_bad_input(capsys):
    assert main(["evaluate", "sim://nosuch", "--seconds", "1"]) == 2
    assert "unknown simulator scenario" in capsys.readouterr().err
    assert main(["evaluate", "sim://static", "--filter", "nonsense"]) == 2
    assert "no filter 'nonsense'" in capsys.readouterr().err


def test_cli_evaluate_runs_without_qt():
    script = textwrap.dedent(
        """
        import sys
        from app.cli import main
        code = main(["evaluate", "sim://static?odr=52&roll=180", "--seconds", "3", "--raw"])
        print("exit", code, "qt", any(m.startswith("PySide6") for m in sys.modules))
        """
    )
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            check=True, timeout=120)
    assert "exit 0 qt False" in result.stdout
    assert "static errors uncompensated" in result.stdout
    for name in FILTERS:
        assert f"  {name} " in result.stdout
