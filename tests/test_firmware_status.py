"""The firmware's STATUS packet (docs/protocol.md, 0x08) and its retry of a failed I2C transfer.

The core runs on the host against the emulated LSM6DSOX in virtual time; what it sends is
decoded by the app's own link decoder. Every expected count comes from what the test did to
the bus or the chip (reads failed, a poll held up), never typed in.
"""

from __future__ import annotations

import numpy as np
from test_firmware_commands import RecordingBus
from test_firmware_streaming import Host, make, start

from drivers.errors import DeviceIOError
from drivers.link import protocol as p
from drivers.link.framing import FrameSplitter, unframe


class GlitchyBus(RecordingBus):
    """Fails the next ``fail_reads`` FIFO reads (FIFO_STATUS or data) before they reach the
    chip, as a glitch on the wires would: the chip's FIFO is untouched."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        self.fail_reads = 0
        self.failed = 0

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        if self.fail_reads and register in (0x3A, 0x78):  # FIFO_STATUS1, FIFO_DATA_OUT_TAG
            self.fail_reads -= 1
            self.failed += 1
            raise DeviceIOError("glitch")
        return super().read_registers(address, register, length)


def statuses(host: Host) -> list[p.Status]:
    return [packet for packet in host.packets if isinstance(packet, p.Status)]


def test_status_is_answered_on_request_and_carries_the_board_layer(firmware_lib) -> None:
    core, _, _ = make(firmware_lib)
    core.set_board_health(uart_rx_errors=3, uart_tx_dropped_bytes=40, i2c_recoveries=2,
                          watchdog_resets=1, reset_cause=5, clock_fallback=True)
    core.send(p.GetStatus())
    (status,) = core.packets()
    assert isinstance(status, p.Status) and status.version == 1
    assert (status.reset_cause_text, status.watchdog_resets) == ("independent watchdog", 1)
    assert (status.uart_rx_errors, status.uart_tx_dropped_bytes) == (3, 40)
    assert status.i2c_recoveries == 2 and status.clock_fallback and status.sensor_ok
    assert not status.streaming
    assert status.fifo_overruns == status.samples_read == status.samples_sent == 0
    core.close()


def test_status_once_a_second_while_streaming_counts_every_sample(firmware_lib) -> None:
    core, _, _ = make(firmware_lib)
    core.send(p.Hello(), p.Configure(5, 4, 500), p.Start())  # 208 Hz
    core.run(3.5)
    frames = [unframe(frame) for frame in FrameSplitter().feed(core.take_output())]
    packets = [p.parse_packet(body[0], body[1:]) for body in frames]
    sent = [packet for packet in packets if isinstance(packet, p.Status)]
    # One right after START, then one a second.
    assert len(sent) == 4 and all(s.streaming for s in sent)
    np.testing.assert_allclose(np.diff([s.uptime_ms for s in sent]), 1000, atol=3)
    # samples_sent is exactly what went out before each STATUS.
    total = 0
    for packet in packets:
        if isinstance(packet, p.Samples):
            total += packet.count
        elif isinstance(packet, p.Status):
            assert packet.samples_sent == total
            assert packet.samples_read >= total
    assert total > 3.4 * 208
    last = sent[-1]
    assert last.fifo_overruns == last.i2c_retries == last.uart_tx_dropped_bytes == 0
    core.close()


def test_a_fifo_overrun_and_a_full_transmit_buffer_are_counted(firmware_lib) -> None:
    core, bus, _ = make(firmware_lib)
    host = Host()
    start(core, host, odr_code=7)  # 833 Hz: the FIFO holds ~0.29 s
    core.run(0.3)
    bus.delay(1.0)  # the firmware is held up for a second: the FIFO overruns
    core.run(0.3)
    core.set_tx_free(0)  # then the host stops reading
    core.run(0.2)
    dropped_bytes = core.counters()["tx_dropped_bytes"]
    core.set_tx_free(64 * 1024)
    core.run(0.2)
    core.send(p.GetStatus())
    host.take(core)
    status = statuses(host)[-1]
    assert status.fifo_overruns == core.counters()["overruns"] == 1
    assert status.uart_tx_dropped_bytes == dropped_bytes > 0
    # What the board read but did not send is what the transmit buffer dropped.
    assert status.samples_read - status.samples_sent > 0
    assert host.decoder.counters().seq_gaps == 2
    core.close()


def test_a_failed_fifo_read_is_retried_and_the_stream_goes_on(firmware_lib) -> None:
    core, _, chip = make(firmware_lib)
    bus = GlitchyBus(chip)
    core.bus = bus
    host = Host()
    start(core, host, odr_code=5)
    core.run(0.5)
    bus.fail_reads = 2  # two failed transfers in a row: the third attempt succeeds
    core.run(0.5)
    bus.fail_reads = 3
    core.run(0.5)
    core.send(p.GetStatus())
    host.take(core)
    assert bus.failed == 5 and core.streaming
    status = statuses(host)[-1]
    assert status.i2c_retries == 5 and status.i2c_errors >= 5
    counters = host.decoder.counters()
    assert counters.seq_gaps == counters.lost_samples == 0  # nothing lost: no gap at all
    assert not host.joined("gap").any()
    logs = [pk for pk in host.packets if isinstance(pk, p.Log) and pk.level == 3]
    assert logs == []
    core.close()


def test_four_failed_transfers_lose_the_sensor_after_three_retries(firmware_lib) -> None:
    core, _, chip = make(firmware_lib)
    bus = GlitchyBus(chip)
    core.bus = bus
    host = Host()
    start(core, host, odr_code=5)
    core.run(0.3)
    bus.fail_reads = 4
    core.run(0.01)
    host.take(core)
    assert not core.streaming
    assert core.counters()["i2c_retries"] == 3
    errors = [pk.text for pk in host.packets if isinstance(pk, p.Log) and pk.level == 3]
    assert errors and "stopped answering" in errors[0]
    core.close()
