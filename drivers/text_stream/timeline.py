"""Device times of a text stream: from its time column, or from the host's arrival times.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.text_stream.layout import Layout
from drivers.text_stream.lexer import TIME_UNITS


class Timeline:
    """Device times from a time column or from host arrival times (see the module docstring)."""

    GAP_FACTOR = 1.5
    MIN_STEP_S = 1e-6
    SILENCE_PERIODS = 5.0
    """On the host's clock, a silence longer than this many sample periods is a gap ..."""
    MIN_SILENCE_S = 0.1
    """... and than this (lines arrive in bursts: a USB serial port delivers every few ms)."""

    def __init__(self) -> None:
        self.origin_s: float | None = None
        self.period_s = 0.01
        self.rate_hz = 100.0
        self.last_t_s: float | None = None
        self.last_raw: float | None = None
        self.last_arrival_s: float | None = None

    def start(self, layout: Layout, period_s: float | None) -> None:
        self.layout = layout
        if period_s is not None:
            self.period_s = period_s
            self.rate_hz = 1.0 / period_s

    def times(
        self, records: dict[str, np.ndarray], layout: Layout
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t_s, lost samples before each, gap flags) for a batch of records."""
        lost = records["lost"].copy()
        if layout.time_unit != "host":
            t, restarted = self._from_column(records["t_raw"] * TIME_UNITS[layout.time_unit], lost)
        else:
            t, restarted = self._from_arrivals(records["arrival"])  # a silence: a gap
        self._learn_rate(t, lost | restarted)
        self.last_t_s = float(t[-1])
        return t, lost, (lost > 0) | restarted

    def _from_column(self, raw_s: np.ndarray, lost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Times from the time column; adds gaps' lost samples to ``lost``; returns restarts."""
        previous = self.last_raw if self.last_raw is not None else raw_s[0]
        steps = np.diff(raw_s, prepend=previous)
        if self.layout.time_unit != "s":  # 32-bit millis()/micros() wrap-around
            wrap = 2.0**32 * TIME_UNITS[self.layout.time_unit]
            steps[steps < -0.5 * wrap] += wrap
        missing = ~np.isfinite(steps)
        restarted = ~missing & (steps < 0)  # the sketch restarted: time went back
        steps[missing | restarted] = self.period_s
        last_t_s = self.last_t_s
        if last_t_s is None:
            steps[0] = 0.0
        t = (0.0 if last_t_s is None else last_t_s) + np.cumsum(steps)
        if last_t_s is not None or len(t) > 1:  # equal stamps (printing faster than the clock)
            ramp = np.arange(len(t)) * self.MIN_STEP_S
            floor = -math.inf if last_t_s is None else last_t_s + self.MIN_STEP_S
            t = np.maximum.accumulate(np.maximum(t, floor) - ramp) + ramp
        finite = raw_s[np.isfinite(raw_s)]
        if len(finite):
            self.last_raw = float(finite[-1])
        long_step = steps > self.GAP_FACTOR * self.period_s
        lost += np.where(long_step, np.maximum(np.rint(steps / self.period_s) - 1, 0), 0).astype(
            np.int64
        )
        return t, restarted

    def _from_arrivals(self, arrival_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arrival times, spread back by the period over lines that came together; t = 0 at
        the first sample; strictly increasing. With them, True on each sample after a silence
        of more than :data:`SILENCE_PERIODS` sample periods (and :data:`MIN_SILENCE_S`): the
        samples are not known to be lost, but nothing may integrate across the hole."""
        n = len(arrival_s)
        last_in_group = np.searchsorted(arrival_s, arrival_s, side="right") - 1
        t = arrival_s - (last_in_group - np.arange(n)) * self.period_s
        if self.origin_s is None:
            self.origin_s = float(t[0])
        t = t - self.origin_s
        floor = (self.last_t_s if self.last_t_s is not None else -math.inf) + self.MIN_STEP_S
        t = np.maximum(t, floor)
        ramp = np.arange(n) * self.MIN_STEP_S
        t = np.maximum.accumulate(t - ramp) + ramp
        steps = np.diff(t, prepend=t[0] if self.last_t_s is None else self.last_t_s)
        silent = steps > max(self.SILENCE_PERIODS * self.period_s, self.MIN_SILENCE_S)
        if self.last_arrival_s is not None and arrival_s[-1] > self.last_arrival_s:
            period = (arrival_s[-1] - self.last_arrival_s) / n
            if period < 4.0 * self.period_s:
                self.period_s = min(1.0, max(1e-4, 0.8 * self.period_s + 0.2 * period))
        self.last_arrival_s = float(arrival_s[-1])
        return t, silent

    def _learn_rate(self, t: np.ndarray, broken: np.ndarray) -> None:
        if self.layout.time_unit == "host":
            self.rate_hz = 1.0 / self.period_s
            return
        steps = np.diff(t)
        steps = steps[(broken[1:] == 0) & (steps > 0)]
        if len(steps):
            self.period_s = 0.8 * self.period_s + 0.2 * float(np.median(steps))
            if self.last_t_s is None:
                self.period_s = float(np.median(steps))
        self.rate_hz = 1.0 / self.period_s


def arrival_period(arrivals: list[float]) -> float | None:
    """Line period from arrival times, when they spread over more than 50 ms."""
    if len(arrivals) >= 2 and arrivals[-1] - arrivals[0] > 0.05:
        return (arrivals[-1] - arrivals[0]) / (len(arrivals) - 1)
    return None
