"""The firmware core with a magnetometer beside the LSM6DSOX (docs/protocol.md, "A magnetometer
beside the sensor"; firmware/core/magnetometer.h).

The core runs in virtual time with an emulated LSM6DSOX at 0x6A and a register-level LIS3MDL
or LIS2MDL (firmware/host/magchips.py) on one bus: the probe, the datasheet configuration
sequence, MAGNETOMETER after CONFIG, every field sample in MAG_SAMPLES equal to the chip's in
order and timed in sensor 0's ticks, the bus budget (the magnetometer paused where two sensors
leave it no room), its I2C errors in STATUS version 2, and the stream read by the app's decoder
and by the decoder from before the extension.
"""

from __future__ import annotations

import numpy as np
from fwcore import FirmwareCore, ForwardingBus, SharedBus
from magchips import EmulatedLis2mdl, EmulatedLis3mdl
from test_magnetometer_link import load_pre_mag_reader

from drivers import lsm6dsox, magnetometers
from drivers.link import protocol as p
from drivers.link.decoder import LinkDecoder
from drivers.link.framing import FrameSplitter, unframe
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.sim.options import SimOptions


class RecordingBus(ForwardingBus):
    """Every register write, per address, in order."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        self.writes: dict[int, list[tuple[int, int]]] = {}

    def write_register(self, address: int, register: int, data: bytes) -> None:
        self.writes.setdefault(address, []).extend(
            (register + i, value) for i, value in enumerate(data))
        super().write_register(address, register, data)


def board(firmware_lib, mag_class=EmulatedLis3mdl, *, sensors: int = 1, baud: int = 921_600):
    clock = VirtualClock(50.0)
    chips = [EmulatedLsm6dsox(SimOptions("static", seed=seed), address=address, clock=clock)
             for seed, address in ((6, 0x6A), (7, 0x6B))[:sensors]]
    mag = mag_class(clock) if mag_class else None
    bus = RecordingBus(SharedBus(*chips, *([mag] if mag else [])))
    return FirmwareCore(firmware_lib, bus, baud=baud), mag, bus


def packets_of(data: bytes) -> list[p.Packet]:
    return [p.parse_packet(body[0], body[1:])
            for body in map(unframe, FrameSplitter().feed(data))]


def test_an_lis3mdl_is_found_configured_by_the_datasheet_and_described(firmware_lib) -> None:
    core, _mag, bus = board(firmware_lib)
    # Soft reset, then ultra-high-performance X/Y at 80 Hz (the fastest not above 104 Hz),
    # +-4 gauss, ultra-high-performance Z, block data update, and continuous conversion last.
    assert bus.writes[0x1C] == [(0x21, 0x04), (0x20, 0x7C), (0x21, 0x00), (0x23, 0x0C),
                                (0x24, 0x40), (0x22, 0x00)]
    core.send(p.Hello())
    hello = core.packets()
    assert [type(pk) for pk in hello] == [p.Info, p.Config, p.Magnetometer]
    assert hello[2] == p.Magnetometer(magnetometers.CHIP_LIS3MDL, 0x1C, 0x3D, 80_000, 400,
                                      magnetometers.LIS3MDL.pt_per_lsb,
                                      magnetometers.MODE_ULTRA_HIGH_PERFORMANCE, 1)
    # The rate follows the accelerometer's: 12.5 Hz (really 13.02) -> 10 Hz.
    core.send(p.Configure(1, 4, 250))
    answer = core.packets()
    assert answer[0] == p.Ack(p.CONFIGURE, p.ACK_OK)
    assert [pk.odr_mhz for pk in answer if isinstance(pk, p.Magnetometer)] == [10_000]
    assert bus.writes[0x1C][-5] == (0x20, 0x70)  # OM = 11, DO = 100: 10 Hz
    core.close()


def test_an_lis2mdl_gets_high_resolution_offset_cancellation_and_bdu(firmware_lib) -> None:
    core, _mag, bus = board(firmware_lib, EmulatedLis2mdl)
    assert bus.writes[0x1E] == [(0x60, 0x20), (0x61, 0x03), (0x62, 0x10), (0x60, 0x8C)]
    core.send(p.Hello())
    (described,) = [pk for pk in core.packets() if isinstance(pk, p.Magnetometer)]
    assert (described.chip, described.i2c_address, described.who_am_i, described.odr_mhz,
            described.range_ut, described.pt_per_lsb) == (2, 0x1E, 0x40, 100_000, 4915, 150_000)
    core.close()


def test_a_board_without_a_magnetometer_sends_what_it_sent_before(firmware_lib) -> None:
    core, _, _ = board(firmware_lib, None)
    core.send(p.Hello(), p.GetStatus())
    packets = core.packets()
    assert [type(pk) for pk in packets] == [p.Info, p.Config, p.Status]
    status = packets[2]
    assert status.version == 1 and status.extra == b"" and status.mag_i2c_errors is None
    # The probes for a magnetometer are no errors: the one failed transfer is the look for a
    # second LSM6DSOX at 0x6B, as before the magnetometer.
    assert status.i2c_errors == 1
    assert core.magnetometer()["found"] is False
    core.close()


def stream(core, seconds: float) -> bytes:
    core.send(p.Start())
    core.run(seconds)
    core.send(p.Stop())
    return core.take_output()


def test_every_field_sample_reaches_the_host_in_order_on_sensor_0s_clock(firmware_lib,
                                                                         tmp_path) -> None:
    core, mag, _ = board(firmware_lib)
    core.send(p.Hello())
    hello = core.take_output()
    wire = stream(core, 1.0)
    packets = packets_of(wire)
    mags = [pk for pk in packets if isinstance(pk, p.MagSamples)]
    assert [pk.seq for pk in mags] == list(range(len(mags)))
    assert core.counters()["mag_overruns"] == 0  # polled every 2 ms: none overwritten
    xyz = np.concatenate([pk.xyz for pk in mags])
    ticks = np.concatenate([pk.t for pk in mags]).astype(np.int64)
    truth = np.array([values for _, values in mag.truth])
    # The chip's samples, consecutive and in order (the first after START is dropped: it may
    # be old), about 80 a second.
    starts = [k for k in range(len(truth)) if np.array_equal(truth[k:k + len(xyz)], xyz)]
    assert starts and 70 <= len(xyz) <= 82
    # Timed on sensor 0's clock: one field period apart, give or take the 2 ms poll.
    tick_s = lsm6dsox.TIMESTAMP_TICK_S
    np.testing.assert_allclose(np.diff(ticks) * tick_s, 1 / 80, atol=0.0025)
    # The app's decoder puts each on an accelerometer row, none late.
    decoder = LinkDecoder()
    decoder.feed(hello)
    decoder.arm_start(new_origin=True)
    decoder.feed(wire)
    blocks = decoder.take_blocks()
    field = np.concatenate([b.mag_raw for b in blocks])
    placed = field[~np.isnan(field[:, 0])]
    counters = decoder.counters()
    assert counters.mag_late == 0 and counters.mag_seq_gaps == 0
    # Those read while the accelerometer's turn-on transient was dropped have no row.
    early = counters.mag_early
    assert 0 < early <= 10  # 0.13 s of discard at 80 Hz
    np.testing.assert_array_equal(placed, xyz[early:early + len(placed)])
    assert len(placed) >= len(xyz) - early - 1  # the last may wait for a row after STOP
    assert blocks[0].scale.mag_ut_per_lsb == magnetometers.LIS3MDL.ut_per_lsb
    status = core.packets()  # nothing after STOP's ACK
    assert status == []
    # A decoder from before the extension reads the same bytes: the accelerometer unchanged.
    old = load_pre_mag_reader(tmp_path).LinkDecoder()
    old.feed(hello)
    old.arm_start(new_origin=True)
    old.feed(wire)
    old_blocks = old.take_blocks()
    for name in ("t_s", "accel_raw", "gyro_raw", "gap"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in old_blocks]),
                                      np.concatenate([getattr(b, name) for b in blocks]))
    old_counts = old.counters()
    assert old_counts.unknown_packets == len(mags) + 1  # MAG_SAMPLES and MAGNETOMETER
    assert old_counts.crc_errors == old_counts.undecodable == old_counts.seq_gaps == 0
    core.close()


def test_the_magnetometer_yields_where_two_sensors_fill_the_bus(firmware_lib) -> None:
    lib = firmware_lib
    # One sensor: room at every rate the board accepts; two at 833 Hz: none (305 + 27 kbit/s
    # of 320); 115200 baud at 833 Hz: none (10.4 + 1.4 kB/s of 11.5).
    assert lib.fw_mag_fits(8, 921_600, 400_000, 1, 80_000)
    assert lib.fw_mag_fits(6, 921_600, 400_000, 2, 80_000)
    assert not lib.fw_mag_fits(7, 921_600, 400_000, 2, 80_000)
    assert not lib.fw_mag_fits(7, 115_200, 400_000, 1, 80_000)
    core, _mag, _ = board(firmware_lib, sensors=2)
    core.send(p.Configure(7, 4, 500))
    answer = core.packets()
    assert answer[0] == p.Ack(p.CONFIGURE, p.ACK_OK)  # the accelerometers keep the rate
    (described,) = [pk for pk in answer if isinstance(pk, p.Magnetometer)]
    assert described.paused and described.answering
    logs = [pk.text for pk in answer if isinstance(pk, p.Log)]
    assert logs == ["magnetometer (LIS3MDL) paused: 833 Hz leaves no room for its 80 Hz on "
                    "the UART or I2C"]
    paused = packets_of(stream(core, 0.2))
    assert not any(isinstance(pk, p.MagSamples) for pk in paused)
    assert any(isinstance(pk, p.SamplesIndexed) for pk in paused)
    core.send(p.Configure(6, 4, 500))
    answer = core.packets()
    assert not next(pk for pk in answer if isinstance(pk, p.Magnetometer)).paused
    assert any(isinstance(pk, p.MagSamples) for pk in packets_of(stream(core, 0.3)))
    core.close()


def test_magnetometer_i2c_errors_are_counted_and_it_comes_back(firmware_lib) -> None:
    core, mag, _ = board(firmware_lib)
    core.send(p.Start())
    core.run(0.2)
    mag.fail = True  # a loose wire: every transfer to it fails
    core.run(0.1)
    core.send(p.GetStatus())
    lost = core.packets()
    status = [pk for pk in lost if isinstance(pk, p.Status)][-1]
    assert status.version == 2 and status.mag_i2c_errors >= 4
    assert status.i2c_errors >= status.mag_i2c_errors
    assert any("magnetometer stopped answering" in pk.text for pk in lost
               if isinstance(pk, p.Log))
    assert any(isinstance(pk, p.Samples) for pk in lost)  # sensor 0 goes on
    mag.fail = False
    core.run(0.7)
    back = core.packets()
    assert any(pk.text == "the magnetometer answers again" for pk in back
               if isinstance(pk, p.Log))
    assert any(isinstance(pk, p.MagSamples) for pk in back)
    core.send(p.GetStatus())
    final = [pk for pk in core.packets() if isinstance(pk, p.Status)][-1]
    assert final.mag_samples_read > status.mag_samples_read
    core.close()


def test_polls_too_late_for_the_field_count_the_samples_the_chip_overwrote(firmware_lib) -> None:
    core, mag, _ = board(firmware_lib)
    core.send(p.Start())
    core.run(0.1)
    core.run(0.5, step_s=0.03)  # a board busy for 30 ms at a time: 80 Hz outruns its polls
    core.send(p.GetStatus())
    status = [pk for pk in core.packets() if isinstance(pk, p.Status)][-1]
    overruns = core.counters()["mag_overruns"]
    assert overruns > 5 and status.mag_overruns == overruns
    assert status.mag_samples_read + overruns <= len(mag.truth)
    core.close()
