"""Decoding the LSM6DSOX FIFO: tagged 7-byte words to samples with times and gaps (numpy).

A FIFO word is a tag byte and 6 data bytes (HARDWARE.md). The tag byte holds TAG_SENSOR[7:3]
(0x01 gyroscope, 0x02 accelerometer, 0x03 temperature, 0x04 timestamp, 0x05 configuration
change), TAG_CNT[2:1] and TAG_PARITY[0] (the byte has even parity). TAG_CNT is a 2-bit counter
of *time slots*: the words of one batch event (gyroscope, accelerometer, and the timestamp or
temperature when batched) share it, and it steps by one per slot. So:

- slot numbers are the running sum of ``(TAG_CNT - previous TAG_CNT) mod 4``, continued across
  bursts; a jump by more than one slot is a loss the decoder can count;
- a sample is a slot with both an accelerometer and a gyroscope word (order does not matter);
- the words of the last slot of a burst stay pending until the slot is complete, because a
  burst may end between the two words;
- timestamp words anchor their slot to the 32-bit tick counter; other slots are placed by the
  tick period per slot measured between anchors (or the configured one);
- after a FIFO overrun the 2-bit counter cannot say how many slots were lost, so slot
  counting restarts and the loss is measured in time from the first new anchor.

All per-word work is vectorised (``np.frombuffer``, masks, ``np.intersect1d``,
``np.searchsorted``); Python only loops over bursts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drivers.lsm6dsox_direct import registers as reg

_EVEN_PARITY = np.array([bin(value).count("1") % 2 == 0 for value in range(256)])
_KNOWN_TAGS = np.array([reg.TAG_GYRO, reg.TAG_ACCEL, reg.TAG_TEMPERATURE, reg.TAG_TIMESTAMP,
                        reg.TAG_CFG_CHANGE])
_ANCHORS_KEPT = 8
_MAX_PENDING_WORDS = 4 * reg.FIFO_CAPACITY_WORDS
_TICK_WRAP = 1 << 32


@dataclass(slots=True)
class DecodedSamples:
    """Samples of one or more bursts.

    Attributes
    ----------
    ticks : (N,) float64 timestamp of each sample in ticks, unwrapped (not yet trimmed).
    accel_raw, gyro_raw : (N, 3) int16 LSB.
    temp_raw : (N,) float64 temperature LSB (the last batched value; NaN before the first).
    lost_before : (N,) int64 samples lost just before each sample.
    """

    ticks: np.ndarray
    accel_raw: np.ndarray
    gyro_raw: np.ndarray
    temp_raw: np.ndarray
    lost_before: np.ndarray

    def __len__(self) -> int:
        return int(self.ticks.shape[0])

    def tail(self, start: int) -> DecodedSamples:
        """The samples from ``start`` on (the ones before are dropped, not lost)."""
        return DecodedSamples(self.ticks[start:], self.accel_raw[start:], self.gyro_raw[start:],
                              self.temp_raw[start:], self.lost_before[start:])


@dataclass(slots=True)
class FifoCounters:
    """What the decoder saw (plain integers; the owner serialises access)."""

    words: int = 0
    parity_errors: int = 0
    unknown_tags: int = 0
    incomplete_slots: int = 0
    overruns: int = 0
    samples: int = 0
    lost_samples: int = 0


@dataclass(slots=True)
class _State:
    prev_cnt: int | None = None
    prev_slot: int = 0
    anchor_slots: list[int] = field(default_factory=list)
    anchor_ticks: list[float] = field(default_factory=list)
    last_raw_ticks: int | None = None
    last_unwrapped_ticks: float = 0.0
    last_sample_slot: int | None = None
    last_sample_ticks: float | None = None
    last_temp_raw: float = float("nan")
    resyncing: bool = False


class FifoDecoder:
    """Turns FIFO bursts into :class:`DecodedSamples` (keeps state across bursts).

    Parameters
    ----------
    ticks_per_slot : the configured slot period in timestamp ticks (40000 / nominal ODR: ticks
        and ODR come from the same trimmed oscillator); replaced by the measured period once
        two anchors are known.
    """

    def __init__(self, ticks_per_slot: float) -> None:
        self.nominal_ticks_per_slot = float(ticks_per_slot)
        self.counters = FifoCounters()
        self._state = _State()
        self._pending = b""

    def reset(self) -> None:
        """Forget everything (after the chip was reconfigured and its FIFO emptied)."""
        self._state = _State()
        self._pending = b""

    def mark_overrun(self) -> None:
        """The chip overwrote unread words: restart slot counting, measure the loss in time."""
        state = self._state
        self.counters.overruns += 1
        self._pending = b""
        state.prev_cnt = None
        state.anchor_slots.clear()
        state.anchor_ticks.clear()
        state.resyncing = state.last_sample_ticks is not None

    @property
    def ticks_per_slot(self) -> float:
        """Measured slot period from the recent anchors, else the configured one."""
        slots, ticks = self._state.anchor_slots, self._state.anchor_ticks
        if len(slots) >= 2 and slots[-1] > slots[0]:
            return (ticks[-1] - ticks[0]) / (slots[-1] - slots[0])
        return self.nominal_ticks_per_slot

    def decode(self, data: bytes) -> DecodedSamples:
        """Decode a burst read from FIFO_DATA_OUT_TAG (a whole number of 7-byte words)."""
        buffer = self._pending + bytes(data)
        usable = len(buffer) - len(buffer) % reg.FIFO_WORD_BYTES
        words = np.frombuffer(buffer, dtype=np.uint8, count=usable).reshape(-1, reg.FIFO_WORD_BYTES)
        self.counters.words += len(words) - len(self._pending) // reg.FIFO_WORD_BYTES
        self._pending = b""
        if len(words) > _MAX_PENDING_WORDS:
            dropped = len(words) - _MAX_PENDING_WORDS
            words = words[dropped:]
            self.counters.incomplete_slots += dropped // 2

        tag_byte = words[:, 0]
        parity_ok = _EVEN_PARITY[tag_byte]
        tag = tag_byte >> 3
        known = np.isin(tag, _KNOWN_TAGS)
        self.counters.parity_errors += int(np.count_nonzero(~parity_ok & (tag_byte != 0)))
        self.counters.unknown_tags += int(np.count_nonzero(parity_ok & ~known & (tag_byte != 0)))
        valid = parity_ok & known
        words = words[valid]
        if len(words) == 0:
            return _empty()
        tag = tag[valid]
        cnt = ((words[:, 0] >> 1) & 0x03).astype(np.int64)
        state = self._state

        # Slot numbers: TAG_CNT steps modulo 4, continued from the previous burst.
        previous = np.empty_like(cnt)
        previous[1:] = cnt[:-1]
        previous[0] = cnt[0] if state.prev_cnt is None else state.prev_cnt
        slot = state.prev_slot + np.cumsum((cnt - previous) % 4)
        if state.prev_cnt is None and state.last_sample_slot is not None:
            slot += state.last_sample_slot + 1 - slot[0]

        is_accel = tag == reg.TAG_ACCEL
        is_gyro = tag == reg.TAG_GYRO
        is_ts = tag == reg.TAG_TIMESTAMP
        is_temp = tag == reg.TAG_TEMPERATURE

        # The last slot stays pending unless it already holds both sensors.
        last = slot[-1]
        in_last = slot == last
        last_complete = bool(np.any(in_last & is_accel) and np.any(in_last & is_gyro))
        keep = np.ones(len(words), dtype=bool) if last_complete else ~in_last

        anchor_slots_new = slot[is_ts & keep]
        no_anchor_yet = not state.anchor_slots and len(anchor_slots_new) == 0
        if no_anchor_yet:
            keep[:] = False  # nothing can be timed yet: wait for the first timestamp word
        if not np.all(keep):
            first_pending = int(np.argmin(keep))  # pending words are the trailing ones
            self._pending = np.ascontiguousarray(words[first_pending:]).tobytes()
            words, tag, slot, cnt = (a[:first_pending] for a in (words, tag, slot, cnt))  # type: ignore[assignment]
            is_accel, is_gyro, is_ts, is_temp = (
                a[:first_pending] for a in (is_accel, is_gyro, is_ts, is_temp)
            )
        if len(words) == 0:
            return _empty()
        state.prev_cnt = int(cnt[-1])
        state.prev_slot = int(slot[-1])

        data16 = np.ascontiguousarray(words[:, 1:]).view("<i2")
        self._add_anchors(slot[is_ts], np.ascontiguousarray(words[is_ts, 1:5]).view("<u4")[:, 0])

        slots_a, first_a = np.unique(slot[is_accel], return_index=True)
        slots_g, first_g = np.unique(slot[is_gyro], return_index=True)
        sample_slots, ia, ig = np.intersect1d(slots_a, slots_g, assume_unique=True,
                                              return_indices=True)
        self.counters.incomplete_slots += len(slots_a) + len(slots_g) - 2 * len(sample_slots)
        if len(sample_slots) == 0:
            return _empty()
        accel_raw = data16[is_accel][first_a[ia]]
        gyro_raw = data16[is_gyro][first_g[ig]]
        temp_raw = self._temperatures(slot[is_temp], data16[is_temp, 0], sample_slots)
        ticks = self._ticks(sample_slots)
        lost = self._losses(sample_slots, ticks)

        state.last_sample_slot = int(sample_slots[-1])
        state.last_sample_ticks = float(ticks[-1])
        self.counters.samples += len(sample_slots)
        self.counters.lost_samples += int(lost.sum())
        return DecodedSamples(ticks, accel_raw, gyro_raw, temp_raw, lost)

    # -- parts ---------------------------------------------------------------------------------
    def _add_anchors(self, slots: np.ndarray, raw_ticks: np.ndarray) -> None:
        """Unwrap the 32-bit counter and remember the newest anchors."""
        if len(slots) == 0:
            return
        state = self._state
        raw = raw_ticks.astype(np.int64)
        first = raw[0] if state.last_raw_ticks is None else state.last_raw_ticks
        steps = np.diff(raw, prepend=first)
        steps[steps < -(_TICK_WRAP // 2)] += _TICK_WRAP
        base = raw[0] if state.last_raw_ticks is None else state.last_unwrapped_ticks
        unwrapped = base + np.cumsum(steps).astype(np.float64)
        state.last_raw_ticks = int(raw[-1])
        state.last_unwrapped_ticks = float(unwrapped[-1])
        state.anchor_slots.extend(int(s) for s in slots[-_ANCHORS_KEPT:])
        state.anchor_ticks.extend(float(t) for t in unwrapped[-_ANCHORS_KEPT:])
        del state.anchor_slots[:-_ANCHORS_KEPT]
        del state.anchor_ticks[:-_ANCHORS_KEPT]

    def unwrap_ticks(self, raw_ticks: int) -> float:
        """A TIMESTAMP register reading (32 bits) on the unwrapped tick axis of the decoded
        samples, taken as the reading nearest the last decoded one."""
        state = self._state
        if state.last_raw_ticks is None:
            return float(raw_ticks)
        step = (int(raw_ticks) - state.last_raw_ticks) % _TICK_WRAP
        if step >= _TICK_WRAP // 2:
            step -= _TICK_WRAP
        return state.last_unwrapped_ticks + step

    def _ticks(self, sample_slots: np.ndarray) -> np.ndarray:
        """Each sample's time: its anchor, or the nearest earlier one plus whole slot periods."""
        state = self._state
        anchor_slots = np.asarray(state.anchor_slots, dtype=np.int64)
        anchor_ticks = np.asarray(state.anchor_ticks, dtype=np.float64)
        index = np.clip(np.searchsorted(anchor_slots, sample_slots, side="right") - 1, 0, None)
        return anchor_ticks[index] + (sample_slots - anchor_slots[index]) * self.ticks_per_slot

    def _temperatures(
        self, temp_slots: np.ndarray, temp_values: np.ndarray, sample_slots: np.ndarray
    ) -> np.ndarray:
        """The latest batched temperature at each sample (forward fill; backfill at start)."""
        state = self._state
        values = temp_values.astype(np.float64)
        before = state.last_temp_raw
        if np.isnan(before) and len(values):
            before = float(values[0])
        if len(values) == 0:
            return np.full(len(sample_slots), before)
        index = np.searchsorted(temp_slots, sample_slots, side="right") - 1
        state.last_temp_raw = float(values[-1])
        return np.where(index >= 0, values[np.clip(index, 0, None)], before)

    def _losses(self, sample_slots: np.ndarray, ticks: np.ndarray) -> np.ndarray:
        """Samples missing before each sample: slot jumps, or time after an overrun."""
        state = self._state
        lost = np.zeros(len(sample_slots), dtype=np.int64)
        lost[1:] = np.diff(sample_slots) - 1
        if state.resyncing and state.last_sample_ticks is not None:
            elapsed_slots = (ticks[0] - state.last_sample_ticks) / self.ticks_per_slot
            lost[0] = max(0, round(elapsed_slots) - 1)
            state.resyncing = False
        elif state.last_sample_slot is not None:
            lost[0] = max(0, int(sample_slots[0]) - state.last_sample_slot - 1)
        return lost


def _empty() -> DecodedSamples:
    return DecodedSamples(
        np.empty(0), np.empty((0, 3), np.int16), np.empty((0, 3), np.int16), np.empty(0),
        np.empty(0, np.int64),
    )
