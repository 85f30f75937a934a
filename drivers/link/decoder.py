"""The streaming decoder of protocol v1: bytes in, packets and :class:`RawBlock` s out.

Feed it whatever the port delivered, in chunks of any size; it cuts frames at 0x00, checks them,
parses them and never raises on garbage (a bad frame is counted and the decoder resynchronises
at the next 0x00). SAMPLES packets are collected and turned into :class:`RawBlock` s with a few
numpy operations per batch (``np.frombuffer`` over the joined sample bytes, never value by
value); every other packet is handed back to the caller.

Time and sequence rules (also in ``docs/protocol.md``)
-------------------------------------------------------
- ``t0`` (u32 ticks) is unwrapped: the forward difference to the previous packet's ``t0``
  modulo 2**32 is added to a running count, so the 29.8 h wrap at 25 us ticks is invisible.
- Sample ``i`` of a packet is at ``t0 + i / ODR``. ``t_s`` is seconds since the first sample
  the decoder saw (``(t0 - t0_first) * tick_ns * 1e-9 + i / ODR``): device time, not host time.
- ``seq`` (u16) must advance by one per SAMPLES packet. A jump of ``d > 1`` is a gap of
  ``k = d - 1`` packets. How many samples they held is not on the wire (count is per packet);
  it is estimated from the timestamps: ``round((t0 - t_end) * tick_s * ODR)`` where ``t_end``
  is where the previous packet's last sample + 1 would be, and never less than ``k`` (every
  packet holds at least one sample). The first sample after the gap gets ``gap=True`` and the
  estimate is added to ``lost_samples``.
- A packet with the same ``seq`` as the previous one is a duplicate: dropped.
- A ``t0`` earlier than the previous one (a forward difference >= 2**31 ticks) means the
  device restarted its clock; a ``t0`` more than half a sample period before the end of the
  previous packet overlaps it. Either way time goes on from the end of the previous packet
  (``t_s`` stays strictly increasing), the sample is marked as a gap (lost samples unknown,
  counted as 0) and one sequence gap is counted.
- A CONFIG with another ``tick_ns`` (never sent by a real device) starts a new time base the
  same way: time goes on from the end of the last packet, with a gap.
- After :meth:`LinkDecoder.arm_start`, SAMPLES are dropped until the ACK of START.

Several sensors on one board (docs/protocol.md, a v1 extension)
--------------------------------------------------------------
A decoder follows one sensor, ``sensor`` (default 0). Sensor 0's samples come in SAMPLES and
its settings in CONFIG, as for any v1 board; sensor ``k > 0``'s samples come in
SAMPLES_INDEXED with index ``k`` and its settings in the SENSOR packet with index ``k``. The
other sensors' sample packets are skipped (counted in ``other_sensor_packets``); sequence
numbers and time are per sensor. SENSOR packets are handed back like any other packet.

Why a gap happened (docs/protocol.md, "Bytes lost on the way")
--------------------------------------------------------------
The ST-LINK has no flow control and loses bytes inside its USB bridge, mid-frame: the host sees
frames that fail their CRC or COBS. The splitter resynchronises at the next 0x00. When the
next good SAMPLES packet shows a sequence gap and corrupt frames came since the previous one,
the gap is the link's (:class:`GapReport` ``cause="link"``, with the count of frames);
otherwise the board dropped the data (``cause="board"``), and its STATUS says why.
"""

from __future__ import annotations

import functools
import math
import struct
from dataclasses import dataclass
from itertools import accumulate

import numpy as np

from app.core.samples import RawBlock, ScaleFactors
from drivers import lsm6dsox
from drivers.link import protocol as p
from drivers.link.framing import FrameSplitter, check_frame

_SAMPLES_HEADER = struct.Struct("<HIBh")
_SAMPLES = p.SAMPLES
_SAMPLE_ROW = np.dtype(("<i2", (6,)))
"""One sample on the wire: gx, gy, gz, ax, ay, az (frombuffer gives (n, 6) int16 rows)."""
_WRAP32 = 1 << 32
_MASK32 = _WRAP32 - 1
_HALF32 = 1 << 31


@dataclass(frozen=True, slots=True)
class LinkCounters:
    """Totals since the decoder was created (a snapshot; see :meth:`LinkDecoder.counters`).

    Attributes
    ----------
    bytes_received : every byte fed in.
    packets : frames that passed COBS, length and CRC checks and parsed.
    samples : samples delivered in :class:`RawBlock` s.
    crc_errors : frames whose CRC did not match.
    undecodable : frames with bad COBS, a length outside 3..512 bytes, a payload that does not
        fit its type, or runs of more than 515 bytes without a 0x00.
    unknown_packets : valid frames of a packet type this host does not know (ignored).
    seq_gaps : sequence gaps (and device clock restarts).
    lost_samples : samples the gaps held (estimated from the timestamps).
    dropped_samples : samples in valid packets that were not delivered: duplicate packets,
        SAMPLES before any CONFIG, or still in flight from a stream before the last START.
    """

    bytes_received: int = 0
    packets: int = 0
    samples: int = 0
    crc_errors: int = 0
    undecodable: int = 0
    unknown_packets: int = 0
    seq_gaps: int = 0
    lost_samples: int = 0
    dropped_samples: int = 0
    link_gaps: int = 0
    """Sequence gaps that corrupt frames (bytes lost on the link) came before."""
    link_lost_samples: int = 0
    """The samples those gaps held (the rest of ``lost_samples`` was lost on the board)."""
    other_sensor_packets: int = 0
    """Valid sample packets of the board's other sensors (skipped by this decoder), counted
    from START's ACK: those still in flight from an earlier stream are not."""
    mag_samples: int = 0
    """Field samples (MAG_SAMPLES) placed on accelerometer rows."""
    mag_seq_gaps: int = 0
    """MAG_SAMPLES sequence gaps (field samples lost on the board or the link)."""
    mag_late: int = 0
    """Field samples that arrived after the rows of their time had been delivered (dropped:
    placed on a later row they would carry the wrong time)."""
    mag_early: int = 0
    """Field samples from before the stream's first accelerometer row (the board reads the
    field while the accelerometer's turn-on transient is discarded): dropped."""


@dataclass(frozen=True, slots=True)
class GapReport:
    """One sequence gap and what the decoder knows about its cause."""

    t_s: float
    """Time of the first sample after the gap."""
    lost_samples: int
    cause: str
    """``"link"``: corrupt frames came before it (bytes lost between board and host);
    ``"board"``: none did (the board dropped the data; its STATUS says why)."""
    corrupt_frames: int = 0

    @property
    def message(self) -> str:
        if self.cause == "link":
            frames = "frame" if self.corrupt_frames == 1 else "frames"
            return (f"link: {self.corrupt_frames} corrupt {frames}, "
                    f"~{self.lost_samples} samples lost")
        return f"board: ~{self.lost_samples} samples lost (a sequence gap)"


def scale_factors(config: p.Config, magnetometer: p.Magnetometer | None = None) -> ScaleFactors:
    """How the raw numbers of a device with this CONFIG (and MAGNETOMETER) become SI units."""
    return _scale_factors(config.accel_fs_g, config.gyro_fs_dps,
                          magnetometer.ut_per_lsb if magnetometer is not None else 1.0)


@functools.lru_cache(maxsize=64, typed=True)
def _scale_factors(accel_fs_g: int, gyro_fs_dps: int, mag_ut_per_lsb: float) -> ScaleFactors:
    """One (immutable) :class:`ScaleFactors` per setting: a decoder is made per connection and
    a CONFIG may come again and again, so they are not computed each time."""
    return ScaleFactors(
        accel_m_s2_per_lsb=lsm6dsox.accel_m_s2_per_lsb(accel_fs_g),
        gyro_rad_s_per_lsb=lsm6dsox.gyro_rad_s_per_lsb(gyro_fs_dps),
        temp_degc_per_lsb=1.0 / lsm6dsox.TEMP_LSB_PER_DEGC,
        temp_offset_degc=lsm6dsox.TEMP_OFFSET_DEGC,
        mag_ut_per_lsb=mag_ut_per_lsb,
    )


@functools.lru_cache(maxsize=64)
def _sample_offsets_s(odr_mhz: int) -> np.ndarray:
    """Time of sample ``i`` of a packet after its first, ``i / ODR`` (read-only, shared)."""
    offsets_s = np.arange(p.MAX_SAMPLES_PER_PACKET) * (1000.0 / odr_mhz)
    offsets_s.flags.writeable = False
    return offsets_s


class LinkDecoder:
    """Bytes from a protocol v1 device -> packets and :class:`RawBlock` s.

    Parameters
    ----------
    config : the device's CONFIG if already known (SAMPLES cannot be converted without one;
        a CONFIG packet in the stream sets or replaces it).
    sensor : which sensor of the board to follow (0: SAMPLES and CONFIG, as in plain v1;
        k > 0: SAMPLES_INDEXED and SENSOR with index k).

    Not thread-safe: one thread feeds; the owner locks if others read :meth:`counters`.
    """

    def __init__(self, config: p.Config | None = None, *, sensor: int = 0) -> None:
        if not 0 <= sensor < p.MAX_SENSORS:
            raise ValueError(f"sensor index {sensor} is not 0..{p.MAX_SENSORS - 1}")
        self.sensor = sensor
        self._other_sensor = 0
        self._splitter = FrameSplitter()
        self._config: p.Config | None = None
        self._scale: ScaleFactors | None = None
        self._ticks_per_sample = 1.0
        self._tick_s = 0.0
        self._blocks: list[RawBlock] = []
        # Counters (plain ints: the hot path must not build objects).
        self._bytes = 0
        self._packets = 0
        self._samples = 0
        self._crc_errors = 0
        self._undecodable = 0
        self._unknown = 0
        self._seq_gaps = 0
        self._lost = 0
        self._dropped = 0
        self._link_gaps = 0
        self._link_lost = 0
        self._corrupt_since_samples = 0
        """Frames that failed COBS, length or CRC since the last good SAMPLES packet."""
        self._oversized_seen = 0
        self._gap_reports: list[GapReport] = []
        self.last_error = ""
        """What was wrong with the most recent rejected frame (for error messages)."""
        # Stream state.
        self._origin_ticks: int | None = None
        """Unwrapped device tick where ``t_s`` equals ``_offset_s`` (None: the next packet)."""
        self._offset_s = 0.0
        self._last_seq: int | None = None
        self._last_t0 = 0
        self._t_ticks = 0
        self._end_ticks = 0.0
        self._last_period_ticks = 0.0
        self._pending_gap = False
        self._armed: tuple[bool, bool] | None = None
        # The magnetometer (MAGNETOMETER, MAG_SAMPLES; sensor 0's board only).
        self._magnetometer: p.Magnetometer | None = None
        self._mag_pending: list[p.MagSamples] = []
        self._mag_last_seq: int | None = None
        self._mag_floor_s = -math.inf
        """Time of the last row delivered: a field sample before it is late."""
        self._mag_samples = 0
        self._mag_gaps = 0
        self._mag_late = 0
        self._mag_early = 0
        self._clear_batch()
        if config is not None:
            self._apply_config(config)

    # -- public API --------------------------------------------------------------------------
    @property
    def config(self) -> p.Config | None:
        return self._config

    @property
    def scale(self) -> ScaleFactors | None:
        return self._scale

    @property
    def magnetometer(self) -> p.Magnetometer | None:
        """The board's MAGNETOMETER once it arrived (blocks then carry ``mag_raw``)."""
        return self._magnetometer

    @property
    def clock_origin_s(self) -> float | None:
        """Device clock time (s, unwrapped from the first packet's ``t0``) where ``t_s`` is 0.

        None before the first sample.
        """
        if self._origin_ticks is None or self._config is None:
            return None
        return self._origin_ticks * self._tick_s - self._offset_s

    def counters(self) -> LinkCounters:
        """A snapshot of the counters."""
        return LinkCounters(
            bytes_received=self._bytes, packets=self._packets, samples=self._samples,
            crc_errors=self._crc_errors,
            undecodable=self._undecodable + self._splitter.oversized,
            unknown_packets=self._unknown, seq_gaps=self._seq_gaps, lost_samples=self._lost,
            dropped_samples=self._dropped, link_gaps=self._link_gaps,
            link_lost_samples=self._link_lost, other_sensor_packets=self._other_sensor,
            mag_samples=self._mag_samples, mag_seq_gaps=self._mag_gaps,
            mag_late=self._mag_late, mag_early=self._mag_early,
        )

    def take_gap_reports(self) -> list[GapReport]:
        """The sequence gaps found since the last call, with their causes, oldest first."""
        reports, self._gap_reports = self._gap_reports, []
        return reports

    def feed(self, data: bytes) -> list[p.Packet]:
        """Decode ``data``; returns the packets other than SAMPLES, in arrival order.

        SAMPLES become blocks: collect them with :meth:`take_blocks`. A CONFIG packet is
        applied (and also returned). Never raises on bad input.
        """
        self._bytes += len(data)
        packets: list[p.Packet] = []
        frames = self._splitter.feed(data)
        if frames and self._splitter.oversized != self._oversized_seen:
            # Runs too long to be frames count as corrupt frames before the first frame after.
            self._corrupt_since_samples += self._splitter.oversized - self._oversized_seen
            self._oversized_seen = self._splitter.oversized
        for frame in frames:
            body = check_frame(frame)
            if isinstance(body, tuple):  # (kind, message) of a bad frame
                if body[0] == "crc":
                    self._crc_errors += 1
                else:
                    self._undecodable += 1
                self._corrupt_since_samples += 1
                self.last_error = body[1]
                continue
            packet_type = body[0]
            count = p.valid_samples_count(body, 1) if packet_type == _SAMPLES else 0
            if count:  # a valid SAMPLES packet (the common case); the rest are sorted below
                self._packets += 1
                if self.sensor == 0:
                    self._on_samples(body, count)
                elif self._armed is None:
                    self._other_sensor += 1
                continue
            if packet_type in (p.SAMPLES, p.SAMPLES_INDEXED):
                try:
                    index, offset = self._samples_index(body)
                    count = p.samples_count(body, offset)
                except p.PacketError as exc:
                    self._reject(exc)
                    continue
                self._packets += 1
                if index == self.sensor:
                    self._on_samples(body, count, offset)
                elif self._armed is None:
                    # Before START's ACK they are left over from an earlier stream, as this
                    # sensor's own are: not the other sensors' packets of this one.
                    self._other_sensor += 1
                continue
            try:
                packet = p.parse_packet(packet_type, body[1:])
            except p.UnknownPacketType as exc:
                self._unknown += 1
                self.last_error = str(exc)
                continue
            except p.PacketError as exc:
                self._reject(exc)
                continue
            self._packets += 1
            if isinstance(packet, p.Config) and self.sensor == 0:
                self._apply_config(packet)
            elif isinstance(packet, p.Sensor) and packet.sensor_index == self.sensor != 0:
                self._apply_config(packet.config)
            elif isinstance(packet, p.Ack):
                self._on_start_ack(packet)
            elif isinstance(packet, p.MagSamples):
                self._on_mag(packet)
                continue
            elif isinstance(packet, p.Magnetometer) and self.sensor == 0:
                self._apply_magnetometer(packet)
            packets.append(packet)
        self._flush()
        return packets

    def take_blocks(self) -> list[RawBlock]:
        """The blocks decoded since the last call (usually one per :meth:`feed`)."""
        blocks, self._blocks = self._blocks, []
        return blocks

    def arm_start(self, *, new_origin: bool, mark_gap: bool = False) -> None:
        """Drop SAMPLES until the device acknowledges START; then the stream starts afresh.

        Call it before sending START: samples still in flight from an earlier stream are
        not mixed into the new one. When the ACK (status ok) arrives, the sequence number is
        forgotten; with ``new_origin`` ``t_s`` restarts at 0 with the next sample, otherwise
        time goes on from the device's timestamps. With ``mark_gap`` the next sample is
        flagged as the first after a gap (the stream was paused, e.g. for a self-test).
        """
        self._flush()
        self._armed = (new_origin, mark_gap)

    def _on_start_ack(self, ack: p.Ack) -> None:
        if self._armed is None or ack.command != p.START:
            return
        new_origin, mark_gap = self._armed
        self._armed = None
        if ack.ok:
            self._last_seq = None
            self._mag_last_seq = None
            if new_origin:
                self._origin_ticks = None
                self._offset_s = 0.0
                self._mag_floor_s = -math.inf
            self._pending_gap = self._pending_gap or mark_gap

    def reset_framing(self) -> None:
        """Drop a partial frame (the port was flushed or reopened)."""
        self._splitter.reset()

    # -- internals ---------------------------------------------------------------------------
    @staticmethod
    def _samples_index(body: bytes) -> tuple[int, int]:
        """(sensor index, offset of the SAMPLES layout) of a SAMPLES or SAMPLES_INDEXED body."""
        if body[0] == p.SAMPLES:
            return 0, 1
        if len(body) < 2 or not 1 <= body[1] < p.MAX_SENSORS:
            index = body[1] if len(body) > 1 else None
            raise p.PacketError(f"SAMPLES_INDEXED with sensor index {index}")
        return body[1], 2

    def _reject(self, exc: Exception) -> None:
        self._undecodable += 1
        self._corrupt_since_samples += 1
        self.last_error = str(exc)

    def _apply_config(self, config: p.Config) -> None:
        if config == self._config:
            return
        self._flush()  # pending samples keep the scale they were measured with
        if (self._origin_ticks is not None and self._config is not None
                and config.tick_ns != self._config.tick_ns):
            # Another tick length is another time base (a real device never changes it):
            # time goes on from the end of the last packet, and a gap is marked.
            self._offset_s += (self._end_ticks - self._origin_ticks) * self._tick_s
            self._origin_ticks = None
            self._last_seq = None
            self._pending_gap = True
        self._config = config
        self._scale = scale_factors(config, self._magnetometer)
        self._ticks_per_sample = 1e12 / (config.odr_mhz * config.tick_ns)
        self._tick_s = config.tick_s

    def _apply_magnetometer(self, magnetometer: p.Magnetometer) -> None:
        if magnetometer == self._magnetometer:
            return
        self._flush()
        self._magnetometer = magnetometer
        if self._config is not None:
            self._scale = scale_factors(self._config, magnetometer)

    def _mag_streams(self) -> bool:
        mag = self._magnetometer
        return mag is not None and mag.answering and not mag.paused

    def _on_mag(self, packet: p.MagSamples) -> None:
        """Keep field samples until the accelerometer rows of their time are flushed."""
        if self.sensor != 0 or not self._mag_streams():
            return  # another sensor's decoder, or no MAGNETOMETER yet: nothing to scale by
        if self._config is None or self._armed is not None:
            return  # before START's ACK: left over from an earlier stream
        if self._mag_last_seq is not None:
            step = (packet.seq - self._mag_last_seq) & 0xFFFF
            if step == 0:
                return  # a duplicate
            if step > 1:
                self._mag_gaps += 1
        self._mag_last_seq = packet.seq
        self._mag_pending.append(packet)
        if len(self._mag_pending) > 4096:  # no accelerometer rows for a long time
            self._mag_late += len(self._mag_pending.pop(0).t)

    def _place_mag(self, t_s: np.ndarray) -> np.ndarray:
        """(n, 3) field counts on the rows ``t_s``: each sample on the first row at or after
        its time, NaN elsewhere; samples after the last row wait for the next block."""
        mag = np.full((t_s.shape[0], 3), np.nan)
        if not self._mag_pending or self._origin_ticks is None:
            return mag
        ticks = np.concatenate([packet.t for packet in self._mag_pending]).astype(np.int64)
        xyz = np.concatenate([packet.xyz for packet in self._mag_pending])
        # Sensor 0's ticks, unwrapped against the latest SAMPLES' t0 (signed difference).
        diff = ((ticks - self._last_t0 + _HALF32) & _MASK32) - _HALF32
        times = self._offset_s + (self._t_ticks + diff - self._origin_ticks) * self._tick_s
        # Times are whole ticks: a sample within half a tick of a row is taken at that row.
        tolerance = 0.5 * self._tick_s + 1e-9
        rows = np.searchsorted(t_s, times - tolerance, side="left")
        if self._mag_floor_s == -math.inf:  # the stream's first rows: nothing before them
            late = times < t_s[0] - tolerance
            self._mag_early += int(np.count_nonzero(late))
        else:
            late = times <= self._mag_floor_s + tolerance  # its row was delivered already
            self._mag_late += int(np.count_nonzero(late))
        placed = ~late & (rows < t_s.shape[0])
        mag[rows[placed]] = xyz[placed]  # in order: two on one row keep the later
        self._mag_samples += int(np.count_nonzero(placed))
        waiting = ~late & ~placed
        self._mag_pending = []
        if waiting.any():
            keep = np.flatnonzero(waiting)
            self._mag_pending.append(p.MagSamples(
                0, (ticks[keep] & _MASK32).astype(np.uint32), xyz[keep]))
        self._mag_floor_s = float(t_s[-1])
        return mag

    def _clear_batch(self) -> None:
        self._starts: list[float] = []
        self._counts: list[int] = []
        self._temps: list[int] = []
        self._gap_packets: list[int] = []
        self._chunks: list[bytes] = []
        self._batch_lost = 0

    def _on_samples(self, body: bytes, count: int, offset: int = 1) -> None:
        if self._config is None or self._armed is not None:
            self._dropped += count
            if self._config is None:
                self.last_error = "SAMPLES before any CONFIG"
            return
        seq, t0, _, temperature = _SAMPLES_HEADER.unpack_from(body, offset)
        gap = self._pending_gap
        lost = 0
        if self._origin_ticks is None:  # the first packet (of this time base)
            t_ticks = t0
            self._origin_ticks = t0
        else:
            forward = (t0 - self._last_t0) & _MASK32
            if self._last_seq is not None and seq == self._last_seq:
                self._dropped += count  # a duplicate packet
                return
            t_ticks = self._t_ticks + forward
            if forward >= _HALF32 or t_ticks < self._end_ticks - 0.5 * self._last_period_ticks:
                # The device clock went back (it restarted) or the packet overlaps the previous
                # one: keep time monotonic, going on from the end of the previous packet.
                t_ticks = math.ceil(self._end_ticks)
                gap = True
                self._seq_gaps += 1
            else:
                if self._last_seq is not None:
                    missing_packets = ((seq - self._last_seq) & 0xFFFF) - 1
                    if missing_packets:
                        estimate = round((t_ticks - self._end_ticks) / self._ticks_per_sample)
                        lost = max(missing_packets, estimate)
                        gap = True
                        self._seq_gaps += 1
                        self._lost += lost
                        corrupt = self._corrupt_since_samples
                        if corrupt:
                            self._link_gaps += 1
                            self._link_lost += lost
                        t_gap = self._offset_s + (t_ticks - self._origin_ticks) * self._tick_s
                        self._gap_reports.append(GapReport(
                            t_gap, lost, "link" if corrupt else "board", corrupt))
        self._corrupt_since_samples = 0
        self._last_seq = seq
        self._last_t0 = t0
        self._t_ticks = t_ticks
        ticks_per_sample = self._ticks_per_sample
        self._end_ticks = t_ticks + count * ticks_per_sample
        self._last_period_ticks = ticks_per_sample
        self._pending_gap = False
        counts = self._counts
        if gap:
            self._gap_packets.append(len(counts))
        self._starts.append(self._offset_s + (t_ticks - self._origin_ticks) * self._tick_s)
        counts.append(count)
        self._temps.append(temperature)
        self._chunks.append(body[offset + p.SAMPLES_HEADER_BYTES:])
        if lost:
            self._batch_lost += lost

    def _flush(self) -> None:
        """Turn the collected SAMPLES packets into one block."""
        if not self._counts:
            return
        config, scale = self._config, self._scale
        assert config is not None and scale is not None
        offsets_s = _sample_offsets_s(config.odr_mhz)
        data = np.frombuffer(b"".join(self._chunks), dtype=_SAMPLE_ROW).astype(np.int16)
        n = data.shape[0]
        gap = np.zeros(n, dtype=bool)
        counts = self._counts
        if len(counts) == 1:  # common at low rates: skip the bookkeeping
            t_s = self._starts[0] + offsets_s[:n]
            temp_raw = np.empty(n, dtype=np.int16)
            temp_raw.fill(self._temps[0])
            gap[0] = bool(self._gap_packets)
        else:
            # Few packets of few samples each: numpy calls, not the rows, are the cost here.
            t_s = np.array(self._starts).repeat(counts) + np.concatenate(
                [offsets_s[:count] for count in counts])
            temp_raw = np.array(self._temps, dtype=np.int16).repeat(counts)
            if self._gap_packets:
                packet_first = list(accumulate(counts, initial=0))
                gap[[packet_first[i] for i in self._gap_packets]] = True
        self._blocks.append(
            RawBlock(
                t_s=t_s,
                accel_raw=data[:, 3:6],
                gyro_raw=data[:, 0:3],
                temp_raw=temp_raw,
                scale=scale,
                gap=gap,
                lost_samples=self._batch_lost,
                mag_raw=self._place_mag(t_s) if self._mag_streams() else None,
            )
        )
        self._samples += n
        self._clear_batch()
