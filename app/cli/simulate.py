"""``inclinometer simulate --pty``: an emulated NUCLEO board on a pseudo-terminal.

The first line printed is the port name alone (scripts read it); the app, or any serial tool,
then connects to that port as to a real board. Serves until Ctrl-C.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import TextIO

from app.cli.errors import CommandError
from drivers import lsm6dsox
from drivers.errors import DeviceError


def add_arguments(simulate: argparse.ArgumentParser) -> None:
    """The options of ``simulate``; it runs :func:`simulate_command`."""
    simulate.set_defaults(handler=simulate_command)
    simulate.description = (
        "Serve the simulator as a NUCLEO board running the Inclinometer firmware would: "
        "protocol v1 (docs/protocol.md) on a new pseudo-terminal, whose name is printed "
        "first. Connect with 'inclinometer --device PORT'. Linux and macOS. Ctrl-C stops."
    )
    simulate.add_argument("--pty", action="store_true",
                          help="serve on a new pseudo-terminal and print its name")
    simulate.add_argument("--scenario", default="wobble",
                          help="simulator scenario (default %(default)s; see 'devices')")
    simulate.add_argument("--odr", type=float, default=104.0, metavar="HZ",
                          help="output data rate at power-on (default %(default)g)")
    simulate.add_argument("--accel-fs", type=int, default=4, metavar="G",
                          help="accelerometer full scale at power-on (default %(default)s)")
    simulate.add_argument("--gyro-fs", type=int, default=250, metavar="DPS",
                          help="gyroscope full scale at power-on (default %(default)s)")
    simulate.add_argument("--seed", type=int, default=1,
                          help="picks the simulated unit, its unique id and USB serial "
                               "(default %(default)s)")
    simulate.add_argument("--baud", type=int, default=921600,
                          help="the board's UART rate: faster ODRs than it carries are "
                               "refused; 0 for native USB, no limit (default %(default)s)")
    simulate.add_argument("--i2c-khz", type=int, default=400, metavar="KHZ",
                          help="the I2C clock the firmware reads the sensor at: faster ODRs "
                               "than it drains are refused, as by the real firmware (above "
                               "1667 Hz at 400 kHz); 0 for no limit (default %(default)s)")
    simulate.add_argument("--sensors", type=int, choices=(1, 2), default=1,
                          help="LSM6DSOX on the board: 2 adds a second one (its own unit, "
                               "seed + 1000) streamed as sensor 1, open it as "
                               "serial://PORT?sensor=1 (default %(default)s)")
    simulate.add_argument("--mag", choices=("none", "lis3mdl", "lis2mdl"), default="none",
                          help="a magnetometer beside the sensor, streamed in MAG_SAMPLES "
                               "(protocol v1 extension; default %(default)s)")
    simulate.add_argument("--fifo-overrun", metavar="SEQ,...", default="",
                          help="lose the samples of these SAMPLES packets (sequence numbers) "
                               "to a sensor FIFO overrun, as the firmware reports one: a gap, "
                               "a LOG and a rise of STATUS's fifo_overruns")


def check_arguments(args: argparse.Namespace) -> None:
    """CommandError for a number no board has (before a port is opened)."""
    problem = lsm6dsox.odr_problem(args.odr)
    if problem is not None:
        raise CommandError(f"--odr {args.odr:g} {problem}")
    for option, value, top in (("--baud", args.baud, 100_000_000),
                               ("--i2c-khz", args.i2c_khz, 100_000),
                               ("--seed", args.seed, 2**63 - 1)):
        if not 0 <= value <= top:
            raise CommandError(f"{option} must be from 0 to {top}")


def simulate_command(args: argparse.Namespace, out: TextIO | None = None,
                     stop: threading.Event | None = None) -> int:
    """Run the ``simulate`` sub-command; returns when ``stop`` is set or on Ctrl-C."""
    out = sys.stdout if out is None else out
    if not args.pty:
        print("inclinometer: simulate needs --pty (the only transport so far)", file=sys.stderr)
        return 2
    check_arguments(args)
    try:
        overruns = frozenset(int(seq) for seq in args.fifo_overrun.split(",") if seq.strip())
    except ValueError:
        print(f"inclinometer: --fifo-overrun wants sequence numbers like 100,250: "
              f"{args.fifo_overrun!r}", file=sys.stderr)
        return 2
    try:
        from drivers.emulated_nucleo import EmulatedNucleo, NucleoFaults

        board = EmulatedNucleo(
            args.scenario, odr_hz=args.odr, accel_fs_g=args.accel_fs, gyro_fs_dps=args.gyro_fs,
            seed=args.seed, baud=args.baud or None,
            sensor_bus_hz=args.i2c_khz * 1000 or None, share_port=True,
            faults=NucleoFaults(overrun_seqs=overruns), sensors=args.sensors,
            mag=None if getattr(args, "mag", "none") == "none" else args.mag,
        )
    except ImportError as exc:
        print(f"inclinometer: pseudo-terminals need Linux or macOS ({exc})", file=sys.stderr)
        return 2
    except (ValueError, DeviceError) as exc:
        print(f"inclinometer: {exc}", file=sys.stderr)
        return 2
    config = board.config
    print(board.port, file=out)
    print(f"Emulated NUCLEO-F746ZG, protocol v1, scenario {args.scenario}, seed {args.seed}: "
          f"unique id {board.unique_id.hex().upper()}, USB serial {board.usb_serial}, "
          f"{config.odr_hz:.3f} Hz (\"{lsm6dsox.odr_label_hz(config.odr_hz):g} Hz\"), "
          f"+-{config.accel_fs_g} g, +-{config.gyro_fs_dps} dps.",
          file=out)
    print(f"Connect with: inclinometer --device {board.port}    (Ctrl-C stops)", file=out)
    mag = board.magnetometer_packet()
    if mag is not None:
        print(f"Magnetometer: {board.mag.name if board.mag else ''} at 0x{mag.i2c_address:02X}, "
              f"{mag.odr_hz:g} Hz" + (" (paused at this rate)" if mag.paused else ""), file=out)
    if args.sensors > 1:
        print(f"Sensor 1 (0x6B, seed {args.seed + 1000}): inclinometer --device "
              f"'serial://{board.port}?sensor=1'", file=out)
        if board.sensor1_paused:
            print(f"Note: {board.pause_message()}; sensor 0 streams alone.", file=out)
    out.flush()
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        # `kill` and `timeout` send SIGTERM: stop as cleanly as on Ctrl-C.
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        board.close()
    stats = board.stats
    print(f"Stopped: {stats.packets_sent} SAMPLES packets, {stats.samples_sent} samples sent, "
          f"{stats.packets_dropped} packets dropped ({stats.tx_dropped_bytes} bytes for want of "
          f"room, {stats.fifo_overruns} FIFO overruns), {stats.status_sent} STATUS, "
          f"{stats.commands} commands.", file=out)
    return 0
