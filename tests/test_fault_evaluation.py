"""``inclinometer evaluate-faults`` (issue 15, item 5): the thesis's NDR and FDI with noise
injected into one channel at a time, and false alarms on clean data. A short sweep (seconds):
NDR rises with sigma on the injected channel and stays near 0 on the clean ones, FDI falls as
sigma grows, a clean source raises nothing, the --json shape and the PNG curves."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.core.faults import CHANNELS, SensorSpec
from app.core.faults.evaluation import (
    estimate_noise_sigma,
    fdi,
    inject,
    ndr,
    run_detector,
    summarize_group,
    sweep_samples,
)
from app.core.faults.injection import FaultSpec
from app.core.samples import SampleBlock
from app.services.fault_evaluation import (
    FaultEvaluationSettings,
    resolve_fault_sources,
    run_fault_evaluation,
)

MULTIPLES = (1.0, 3.0, 10.0, 30.0)
CHANNELS_SWEPT = ("ax", "az", "gy")
SAMPLE_RECORDING = Path(__file__).resolve().parents[1] / "resources" / "recordings" \
    / "wobble-104hz.csv"


@pytest.fixture(scope="module")
def short_sweep():
    """20 s of the simulator at rest, noise from 5 s, three channels, four sigmas."""
    settings = FaultEvaluationSettings(seconds=20.0, onset_s=5.0, clean_seconds=20.0,
                                       multiples=MULTIPLES, channels=CHANNELS_SWEPT)
    return run_fault_evaluation(resolve_fault_sources(["sim://static?seed=3"]), settings)


def test_ndr_and_fdi_count_flagged_samples() -> None:
    flags = np.zeros((6, 6), dtype=np.uint8)
    flags[[2, 4, 5], 1] = 4
    flags[5, 3] = 16
    assert ndr(flags).tolist() == [0.0, 0.5, 0.0, 1 / 6, 0.0, 0.0]
    assert ndr(flags, start=4)[1] == 1.0
    assert fdi(flags[:, 1] != 0, (1, 2, 3, 4)) == {1: 3, 2: 5, 3: 6, 4: None}


def test_ndr_rises_with_sigma_on_the_injected_channel_only(short_sweep) -> None:
    (group,) = short_sweep.groups
    assert group.name == "simulator" and group.multiples == list(MULTIPLES)
    for name in CHANNELS_SWEPT:
        c = CHANNELS.index(name)
        on = group.ndr_injected(c)
        assert np.all(np.diff(on) >= -0.02), (name, on)  # rises (up to sampling wobble)
        assert on[0] < 0.05 and on[-1] > 0.8, (name, on)  # own noise: not a fault; 30x is
        assert max(group.ndr_others_max(c)) <= 0.01, (name, group.ndr[c])


def test_fdi_falls_as_sigma_grows(short_sweep) -> None:
    (group,) = short_sweep.groups
    for theta in (1, 10, 100):
        for c in group.channels:
            values = group.fdi[theta][c]
            assert values[0] is None, (theta, CHANNELS[c], values)  # 1x is never declared
            declared = [v for v in values if v is not None]
            assert len(declared) >= 2 and values[-1] is not None, (theta, CHANNELS[c], values)
            assert all(a >= b for a, b in itertools.pairwise(declared)), values
            assert values[-1] >= theta
    # a larger theta waits at least as long
    for c in group.channels:
        assert group.fdi[100][c][-1] >= group.fdi[10][c][-1] >= group.fdi[1][c][-1]


def test_a_clean_source_raises_no_false_alarm(short_sweep) -> None:
    (sweep,) = short_sweep.sweeps
    assert sweep.clean_events == [] and sweep.false_alarms == 0
    assert np.all(sweep.clean_ndr == 0.0)
    assert short_sweep.groups[0].false_alarms_per_hour == 0.0


def test_injection_touches_one_channel_from_the_onset() -> None:
    n = 400
    t = np.arange(n) / 100.0
    samples = SampleBlock(t, np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3)), np.zeros(n),
                          np.zeros(n, bool))
    faulty = inject(samples, [FaultSpec("noise", "gy", 1.0, 2.0)], seed=4)
    assert np.array_equal(faulty.accel_m_s2, samples.accel_m_s2)
    assert np.all(faulty.gyro_rad_s[:200] == 0.0) and np.all(faulty.gyro_rad_s[:, [0, 2]] == 0)
    assert 0.8 < np.degrees(faulty.gyro_rad_s[200:, 1]).std() < 1.2
    quantised = inject(samples, [FaultSpec("noise", "ax", 0.01, 0.0)], lsb=np.full(6, 0.01))
    assert np.allclose(quantised.accel_m_s2[:, 0] / 0.01, np.rint(quantised.accel_m_s2[:, 0]
                                                                  / 0.01))


def test_own_noise_is_estimated_from_the_quiet_parts() -> None:
    rng = np.random.default_rng(2)
    n = 6000
    x = rng.standard_normal((n, 2)) * [0.01, 0.002]
    x[2000:3000, 0] += 5.0 * np.sin(np.arange(1000) * 0.3)  # a burst of motion
    sigma = estimate_noise_sigma(x, 100.0)
    assert sigma == pytest.approx([0.01, 0.002], rel=0.1)


def test_sweep_of_samples_without_a_datasheet_estimates_the_noise() -> None:
    from app.core.recording.reader import read_recording
    from app.services.diagnosis import recording_spec

    recording = read_recording(SAMPLE_RECORDING)
    samples = recording.sample_block(None)
    spec = recording_spec(recording)
    unknown = SensorSpec(odr_hz=spec.odr_hz)
    sweep = sweep_samples(samples, unknown, label="wobble", group="r", onset_s=5.0,
                          channels=(4,), multiples=(1.0, 100.0))
    assert sweep.noise_basis == "estimated at rest" and np.all(sweep.noise_si > 0)
    assert [r.multiple for r in sweep.runs] == [1.0, 100.0]
    assert sweep.false_alarms == 0
    assert run_detector(samples, unknown).flags.shape == (len(samples), 6)
    group = summarize_group("r", [sweep])
    assert group.channels == [4] and len(group.ndr[4]) == 2


def test_cli_json_shape_and_png_curves(tmp_path, capsys) -> None:
    out = tmp_path / "faults.json"
    pngs = tmp_path / "png"
    status = main(["evaluate-faults", "sim://static?seed=3", str(SAMPLE_RECORDING),
                   "--seconds", "14", "--onset", "4", "--clean-seconds", "20",
                   "--sigma", "1,20", "--channels", "ay,gx", "--json", str(out),
                   "--png", str(pngs), "--quiet"])
    printed = capsys.readouterr().out
    assert status == 0
    for title in ("NDR on the injected channel", "NDR on the other five channels",
                  "NDR matrix", "FDI: samples", "theta = 100", "False alarms on the clean"):
        assert title in printed
    document = json.loads(out.read_text())
    assert set(document) == {"measure", "settings", "groups", "sources"}
    assert document["settings"]["sigma_multiples"] == [1.0, 20.0]
    assert set(document["groups"]) == {"simulator", "recordings"}
    sim = document["groups"]["simulator"]
    assert sim["channels"] == ["ay", "gx"] and sim["thetas"] == [1, 10, 100]
    assert len(sim["ndr_injected"]["ay"]) == 2 and len(sim["ndr_others_max"]["gx"]) == 2
    assert set(sim["ndr"]["gx"][1]) == set(CHANNELS)
    assert set(sim["fdi_samples"]) == {"1", "10", "100"}
    assert isinstance(sim["fdi_samples"]["1"]["ay"][1], float)
    assert sim["clean"]["false_alarms"] == 0 and sim["clean"]["per_hour"] == 0.0
    source = document["sources"][0]
    assert source["group"] == "simulator" and len(source["injections"]) == 4
    assert source["own_noise_basis"] == "datasheet"
    assert set(source["injections"][0]) == {"channel", "multiple", "sigma", "unit", "ndr",
                                             "fdi", "first_event_s"}
    assert {i["unit"] for i in source["injections"]} == {"g", "dps"}
    assert document["sources"][1]["clean"]["false_alarms"] == 0
    _check_pngs(pngs, ["ndr_simulator.png", "fdi_simulator.png", "ndr_recordings.png",
                       "fdi_recordings.png"])


def _check_pngs(directory: Path, names: list[str]) -> None:
    from PySide6.QtGui import QImage

    assert sorted(p.name for p in directory.iterdir()) == sorted(names)
    for name in names:
        path = directory / name
        assert path.stat().st_size > 10_000, name
        image = QImage(str(path))
        assert not image.isNull() and image.width() >= 800 and image.height() >= 400
        pixels = image.convertToFormat(QImage.Format.Format_RGB32)
        data = np.frombuffer(pixels.constBits(), dtype=np.uint32,
                             count=pixels.width() * pixels.height())
        colours, counts = np.unique(data, return_counts=True)
        assert len(colours) > 50, name  # text, grid, curves in several colours
        assert counts.max() < 0.97 * data.size, name  # not all background


@pytest.mark.parametrize(("arguments", "message"), [
    (["sim://nowhere"], "unknown simulator scenario"),
    (["serial:///dev/ttyACM0"], "only simulator URLs"),
    (["no/such/recording.csv"], "no such file"),
    (["sim://static", "--onset", "30", "--seconds", "20"], "--onset must be"),
    (["sim://static", "--channels", "qx"], "unknown channel 'qx'"),
])
def test_cli_refuses_what_it_cannot_sweep(arguments, message, capsys) -> None:
    assert main(["evaluate-faults", *arguments]) == 2
    assert message in capsys.readouterr().err
