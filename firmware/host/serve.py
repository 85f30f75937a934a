"""Serve the firmware's portable core on a pseudo-terminal, with the emulated LSM6DSOX behind it.

The real firmware core (COBS, CRC, commands, the LSM6DSOX sequence, FIFO streaming), built for
this machine, in real time, so the app connects to it exactly as to a NUCLEO board:

    python firmware/host/serve.py --scenario wobble
    inclinometer --device /dev/pts/7            # the port it prints

With ``--sensors 2`` a second emulated LSM6DSOX (seed + 1000) sits at 0x6B on the same bus:
open it as ``serial:///dev/pts/7?sensor=1``. With ``--mag lis3mdl`` (or ``lis2mdl``) a
register-level magnetometer (``magchips.py``) sits beside it: the firmware streams its field.

Needs gcc and make (it builds the host library into a temporary folder). Ctrl+C stops it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for drivers/

from fwcore import FirmwareCore, PtyBoard, SharedBus, build_library
from magchips import EmulatedLis2mdl, EmulatedLis3mdl

from drivers.lsm6dsox_direct.emulated_chip import EmulatedLsm6dsox
from drivers.sim import SCENARIOS
from drivers.sim.options import SimOptions


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="wobble", choices=sorted(SCENARIOS))
    parser.add_argument("--seed", type=int, default=1, help="picks the simulated unit")
    parser.add_argument("--baud", type=int, default=921_600,
                        help="the UART rate the firmware limits the ODR by (0: native USB)")
    parser.add_argument("--i2c-hz", type=int, default=400_000,
                        help="the I2C clock the firmware limits the ODR by (0: no limit)")
    parser.add_argument("--sensors", type=int, choices=(1, 2), default=1,
                        help="LSM6DSOX on the bus: 2 puts a second one at 0x6B (sensor 1)")
    parser.add_argument("--mag", choices=("none", "lis3mdl", "lis2mdl"), default="none",
                        help="a magnetometer on the bus: an LIS3MDL at 0x1C or an LIS2MDL at "
                             "0x1E")
    args = parser.parse_args(argv)
    mags = {"lis3mdl": EmulatedLis3mdl, "lis2mdl": EmulatedLis2mdl}
    with tempfile.TemporaryDirectory(prefix="inclinometer-fw-") as build:
        lib = build_library(Path(build))

        def core() -> FirmwareCore:
            chips = [EmulatedLsm6dsox(SimOptions(args.scenario, seed=args.seed + 1000 * k),
                                      address=0x6A + k) for k in range(args.sensors)]
            if args.mag in mags:
                chips.append(mags[args.mag](time.monotonic))
            return FirmwareCore(lib, SharedBus(*chips), baud=args.baud, i2c_hz=args.i2c_hz)

        board = PtyBoard(core)
        print(f"firmware core on {board.port}: inclinometer --device {board.port}", flush=True)
        if args.sensors > 1:
            print(f"sensor 1: inclinometer --device 'serial://{board.port}?sensor=1'",
                  flush=True)
        try:
            threading.Event().wait()
        except KeyboardInterrupt:
            pass
        finally:
            board.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
