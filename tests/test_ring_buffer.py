"""Ring buffers keep the newest rows in order, never grow, and find time windows."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from app.core.ring_buffer import RingBuffer


def make(capacity: int = 10) -> RingBuffer:
    return RingBuffer(capacity, {"t": 1, "v": 3})


def rows(start: int, count: int) -> dict[str, np.ndarray]:
    t = np.arange(start, start + count, dtype=float)
    return {"t": t, "v": np.stack([t, 2 * t, 3 * t], axis=1)}


def test_latest_returns_newest_rows_oldest_first_across_the_wrap():
    ring = make(10)
    for start in range(0, 27, 3):
        ring.write(rows(start, 3))
    assert len(ring) == 10
    assert ring.total_written == 27
    got = ring.latest(10)
    np.testing.assert_array_equal(got["t"], np.arange(17, 27))
    np.testing.assert_array_equal(got["v"][:, 2], 3 * np.arange(17, 27))
    np.testing.assert_array_equal(ring.latest(4)["t"], np.arange(23, 27))


def test_a_block_larger_than_the_capacity_keeps_its_tail():
    ring = make(10)
    ring.write(rows(0, 25))
    np.testing.assert_array_equal(ring.latest(100)["t"], np.arange(15, 25))


def test_window_selects_by_time_and_handles_empty():
    ring = make(50)
    assert len(ring.window(5.0)["t"]) == 0
    for start in range(0, 80, 7):
        ring.write(rows(start, 7))
    newest = 83.0
    got = ring.window(10.0)
    assert got["t"][0] == newest - 10.0
    assert got["t"][-1] == newest
    assert len(ring.window(1e9)["t"]) == 50


def test_clear_and_validation():
    ring = make(5)
    ring.write(rows(0, 3))
    ring.clear()
    assert len(ring) == 0 and ring.total_written == 0
    with pytest.raises(ValueError, match="rows"):
        ring.write({"t": np.zeros(3), "v": np.zeros((2, 3))})
    with pytest.raises(ValueError, match="time column"):
        RingBuffer(5, {"v": 3})


def test_concurrent_writer_and_reader_see_consistent_rows():
    ring = make(1000)
    stop = threading.Event()
    errors: list[str] = []

    def reader() -> None:
        while not stop.is_set():
            got = ring.latest(500)
            if len(got["t"]) and not np.array_equal(got["v"][:, 1], 2 * got["t"]):
                errors.append("torn row")
            if len(got["t"]) > 1 and np.any(np.diff(got["t"]) != 1.0):
                errors.append("out of order")

    thread = threading.Thread(target=reader)
    thread.start()
    for start in range(0, 200_000, 97):
        ring.write(rows(start, 97))
    stop.set()
    thread.join()
    assert errors == []
