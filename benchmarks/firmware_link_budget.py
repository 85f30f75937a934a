"""The firmware's traffic at every output data rate: the I2C bus and the UART, measured.

The firmware's own core (built for this machine) streams from the emulated LSM6DSOX on virtual
time, with its rate limits switched off, and every I2C transfer and every byte it sends is
counted. Bits on I2C: per transfer a START, the address byte(s), the register byte and a STOP
(a read also a repeated START and a second address), 9 bits per byte. The UART carries 10 bits
per byte (8N1). The last columns say whether the firmware accepts the rate on the NUCLEO
(921600 baud, I2C at 400 kHz), by its own rule (fw_rate_fits).

    .venv/bin/python benchmarks/firmware_link_budget.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware" / "host"))

from fwcore import FirmwareCore, ForwardingBus, build_library, rate_fits

from drivers import lsm6dsox
from drivers.link import protocol as p
from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox, VirtualClock
from drivers.sim.options import SimOptions

BAUD = 921_600
I2C_HZ = 400_000


class CountingBus(ForwardingBus):
    """Counts the bits each transfer puts on the bus."""

    def __init__(self, inner: EmulatedLsm6dsox) -> None:
        super().__init__(inner)
        self.bits = 0
        self.transfers = 0

    def write_register(self, address: int, register: int, data: bytes) -> None:
        super().write_register(address, register, data)
        self.transfers += 1
        self.bits += 1 + 9 * (2 + len(data)) + 1  # START, address, register, data, STOP

    def read_registers(self, address: int, register: int, length: int) -> bytes:
        data = super().read_registers(address, register, length)
        self.transfers += 1
        self.bits += 1 + 9 * 2 + 1 + 9 * (1 + length) + 1  # ..., Sr, address, data, STOP
        return data


def measure(lib, odr_code: int, seconds: float) -> dict[str, float]:
    chip = EmulatedLsm6dsox(SimOptions("wobble", seed=3), clock=VirtualClock(1.0))
    bus = CountingBus(chip)
    core = FirmwareCore(lib, bus, baud=0, i2c_hz=0)  # limits off: measure every rate
    core.send(p.Configure(odr_code, 4, 500), p.Start())
    core.take_output()
    core.run(0.5)  # settle
    core.take_output()
    bits0, transfers0, samples0 = bus.bits, bus.transfers, core.counters()["samples"]
    core.run(seconds)
    uart_bytes = len(core.take_output())
    counters = core.counters()
    core.close()
    return {
        "samples_s": (counters["samples"] - samples0) / seconds,
        "uart_bytes_s": uart_bytes / seconds,
        "i2c_bits_s": (bus.bits - bits0) / seconds,
        "transfers_s": (bus.transfers - transfers0) / seconds,
        "packets_s": counters["packets"] / (seconds + 0.5),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="virtual seconds per rate")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as build:
        lib = build_library(Path(build))
        print(f"{'ODR':>7} {'samples/s':>10} {'UART B/s':>9} {'UART %':>7} {'I2C kbit/s':>10} "
              f"{'I2C %':>6} {'xfers/s':>8}  NUCLEO (921600 baud, I2C 400 kHz)")
        for code, hz in lsm6dsox.ODR_LABELS_HZ.items():  # labels; the chip runs 6666.67 / 2^k
            m = measure(lib, code, args.seconds)
            fits, why = rate_fits(lib, code, BAUD, I2C_HZ)
            verdict = "accepted" if fits else f"refused: {why.split(';')[0]}"
            print(f"{hz:>7g} {m['samples_s']:>10.1f} {m['uart_bytes_s']:>9.0f} "
                  f"{100 * m['uart_bytes_s'] * 10 / BAUD:>6.1f}% {m['i2c_bits_s'] / 1e3:>10.1f} "
                  f"{100 * m['i2c_bits_s'] / I2C_HZ:>5.1f}% {m['transfers_s']:>8.0f}  {verdict}")


if __name__ == "__main__":
    main()
