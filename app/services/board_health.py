"""The board's own health (link protocol v1 STATUS) turned into messages with their reasons.

A NUCLEO board sends its counters once a second while streaming. :class:`BoardHealth` keeps the
latest, the first of the session and the first of a recording, and turns a rise between two
into a message for the user: "board: sensor FIFO overrun, 12 samples lost", "board: UART
dropped 512 bytes", "board: I2C retried 3 times". The samples lost are the host's own count of
sequence gaps that no corrupt frame explains (lost on the board), over the same second. No Qt.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.core.devices import BoardStatus

WARNING = 2
INFO = 1
KEY_STATUS_START = "board_status_start"
KEY_STATUS_END = "board_status_end"
"""Recording metadata (docs/recording-format.md): the board's counters at start and end."""


@dataclass(frozen=True, slots=True)
class BoardMessage:
    level: int
    """1 info, 2 warning (as a board's LOG levels)."""
    text: str


def _times(n: int) -> str:
    return "once" if n == 1 else f"{n} times"


def describe_rise(before: BoardStatus, after: BoardStatus) -> list[BoardMessage]:
    """What happened on the board between two STATUS packets of the same power-on."""
    rise = {name: after.rise(before, name) for name in BoardStatus.COUNTERS}
    lost = max(0, after.host_gap_samples - before.host_gap_samples)
    messages: list[BoardMessage] = []
    causes = []
    if rise["fifo_overruns"]:
        overruns = rise["fifo_overruns"]
        causes.append("sensor FIFO overrun" + ("" if overruns == 1 else f" ({overruns} times)"))
    if rise["uart_tx_dropped_bytes"]:
        causes.append(f"UART dropped {rise['uart_tx_dropped_bytes']} bytes (the computer did "
                      "not read fast enough)")
    if causes:
        tail = f", {lost} samples lost" if lost else ""
        messages.append(BoardMessage(WARNING, "board: " + " and ".join(causes) + tail))
    elif lost:
        messages.append(BoardMessage(
            WARNING, f"board: {lost} samples lost, and its counters give no reason"))
    if rise["i2c_retries"]:
        messages.append(BoardMessage(
            INFO, f"board: I2C retried {_times(rise['i2c_retries'])} (glitches on the sensor's "
                  "bus; no data lost)"))
    errors = rise["i2c_errors"] - rise["i2c_retries"]
    if errors > 0:
        messages.append(BoardMessage(WARNING, f"board: {errors} failed I2C transfers"))
    if rise["mag_i2c_errors"]:
        messages.append(BoardMessage(
            WARNING, f"board: {rise['mag_i2c_errors']} failed I2C transfers to the "
                     "magnetometer (field samples lost)"))
    if rise["i2c_recoveries"]:
        messages.append(BoardMessage(
            WARNING, f"board: I2C bus stuck and recovered {_times(rise['i2c_recoveries'])}"))
    if rise["uart_rx_errors"]:
        messages.append(BoardMessage(
            WARNING, f"board: UART received {rise['uart_rx_errors']} bad bytes (commands may "
                     "need repeating)"))
    return messages


def describe_start(status: BoardStatus) -> list[BoardMessage]:
    """What the first STATUS of a board (or of a restart) says worth telling."""
    messages = []
    if status.reset_cause in ("independent watchdog", "window watchdog"):
        messages.append(BoardMessage(
            WARNING, f"board: restarted by its watchdog ({status.watchdog_resets} watchdog "
                     "resets since power-on): the firmware hung"))
    if status.clock_fallback:
        messages.append(BoardMessage(
            WARNING, "board: running on its internal oscillator (no clock from the ST-LINK): "
                     "its UART is about 2 % off"))
    return messages


class BoardHealth:
    """The connected board's STATUS: latest, first, and the messages a new one brings."""

    def __init__(self) -> None:
        self.latest: BoardStatus | None = None
        self.first: BoardStatus | None = None
        self._changed = False

    def reset(self) -> None:
        """Another device: forget the board."""
        self.latest = self.first = None
        self._changed = True

    def update(self, status: BoardStatus | None) -> list[BoardMessage]:
        """A status from the device (the same one again is ignored); returns the messages."""
        if status is None or status is self.latest:
            return []
        previous, self.latest = self.latest, status
        self._changed = True
        if previous is None:
            self.first = status
            return describe_start(status)
        if status.restarted_since(previous):
            return [BoardMessage(WARNING, f"board: restarted ({status.reset_cause}); its "
                                          "counters start again"), *describe_start(status)]
        return describe_rise(previous, status)

    def start_metadata(self) -> dict:
        """``{"board_status_start": {...}}`` for a recording starting now (empty without)."""
        return {} if self.latest is None else {KEY_STATUS_START: self.latest.as_dict()}

    def end_metadata(self) -> dict:
        """``{"board_status_end": {...}}`` for a recording ending now (empty without)."""
        return {} if self.latest is None else {KEY_STATUS_END: self.latest.as_dict()}

    def take_changed(self) -> BoardStatus | None:
        """The latest status if it changed since the last call, else None."""
        if not self._changed:
            return None
        self._changed = False
        return self.latest
