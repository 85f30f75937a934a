"""The compiled CSV number parser: every value exactly as Python's ``float`` reads it."""

from __future__ import annotations

import decimal

import numpy as np
import pytest

from app.core.recording import fast_csv


def parse_column(strings: list[str], kind: int = fast_csv.KIND_OPTIONAL):
    """Parse one column of ``strings`` with the kernel; slow cells through ``float``."""
    text = ("\n".join(strings) + "\n").encode()
    buf = np.frombuffer(text, dtype=np.uint8)
    n = len(strings)
    values = np.empty(n)
    flags = np.zeros(n, dtype=np.uint8)
    offsets = np.zeros(n, dtype=np.int64)
    result = fast_csv.parse_body(
        buf, 0, len(text), np.array([kind], np.int8), 0, n, values, values.view(np.int64),
        flags, offsets, fast_csv.POW5_HIGH, fast_csv.POW5_LOW, fast_csv.EXACT_POWERS_OF_TEN)
    for index in np.flatnonzero(flags == fast_csv.FLAG_SLOW):
        values[index] = float(strings[index])
    return result, values, flags


def assert_bits_equal(strings: list[str]) -> np.ndarray:
    result, got, flags = parse_column(strings)
    assert result == (len(strings), fast_csv.ERROR_NONE, -1, -1)
    want = np.array([float(s) for s in strings])
    mismatched = np.flatnonzero(got.view(np.int64) != want.view(np.int64))
    assert len(mismatched) == 0, [strings[i] for i in mismatched[:5]]
    return flags


def test_random_doubles_written_with_repr_read_back_bit_for_bit():
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**63, 300_000, dtype=np.int64)
    bits |= rng.integers(0, 2, bits.shape, dtype=np.int64) << 63
    values = bits.view(np.float64)
    values = values[np.isfinite(values)]
    flags = assert_bits_equal([repr(v) for v in values.tolist()])
    # Nearly all go through the compiled paths (only subnormals and the like are left over).
    assert np.count_nonzero(flags) < 0.01 * len(values)


def test_quantised_sensor_values_never_need_the_slow_path():
    lsb_sizes = (0.122e-3 * 9.80665, 0.488e-3 * 9.80665, float(np.radians(8.75e-3)),
                 float(np.radians(70e-3)))
    counts = np.arange(-32768, 32768, 3)
    strings = [repr(k * s) for s in lsb_sizes for k in counts.tolist()]
    flags = assert_bits_equal(strings)
    assert not flags.any()


def test_other_spellings_long_digit_strings_and_exact_halfway_cases():
    rng = np.random.default_rng(3)
    values = rng.normal(0.0, 1e3, 20_000).tolist()
    strings = [f"{v:.17g}" for v in values] + [f"{v:.25e}" for v in values[:2000]]
    strings += [f"{v:.3f}" for v in values[:2000]] + [f"{v:E}" for v in values[:2000]]
    # Exact midpoints between neighbouring doubles must round to even.
    for v in rng.uniform(1e-3, 1e12, 500).tolist():
        midpoint = decimal.Decimal(v) + decimal.Decimal(float(np.spacing(v))) / 2
        strings.append(format(midpoint, "f"))
    strings += [
        "9007199254740993", "9007199254740995", "2.2250738585072011e-308", "4.9e-324",
        "1.7976931348623157e308", "1.7976931348623159e308", "1e400", "1e-400", "-0.0", "0",
        "00.000", ".5", "5.", "+1.5", "-.5e1", "123456789012345678901234567890",
        "0.000000000000000000000000000001", "1.00000000000000011102230246251565404236316680908",
    ]
    assert_bits_equal(strings)


def test_special_words_spaces_empty_fields_and_crlf():
    text = b" nan , -INF,+Infinity\r\n,1e3 ,\n"
    buf = np.frombuffer(text, dtype=np.uint8)
    values = np.empty(6)
    flags = np.zeros(6, dtype=np.uint8)
    kinds = np.array([fast_csv.KIND_OPTIONAL] * 3, np.int8)
    result = fast_csv.parse_body(
        buf, 0, len(text), kinds, 0, 2, values, values.view(np.int64), flags,
        np.zeros(2, np.int64), fast_csv.POW5_HIGH, fast_csv.POW5_LOW,
        fast_csv.EXACT_POWERS_OF_TEN)
    assert result[:2] == (2, fast_csv.ERROR_NONE)
    table = values.reshape(3, 2)  # column-major: (column, row)
    assert np.isnan(table[0, 0]) and table[1, 0] == -np.inf and table[2, 0] == np.inf
    assert np.isnan(table[0, 1]) and table[1, 1] == 1000.0 and np.isnan(table[2, 1])


@pytest.mark.parametrize(
    ("line", "kind", "error"),
    [
        (b"1.5x\n", fast_csv.KIND_OPTIONAL, fast_csv.ERROR_NUMBER),
        (b"1e\n", fast_csv.KIND_OPTIONAL, fast_csv.ERROR_NUMBER),
        (b"--1\n", fast_csv.KIND_OPTIONAL, fast_csv.ERROR_NUMBER),
        (b"1.2.3\n", fast_csv.KIND_OPTIONAL, fast_csv.ERROR_NUMBER),
        (b"nanx\n", fast_csv.KIND_OPTIONAL, fast_csv.ERROR_NUMBER),
        (b" \t,\n", fast_csv.KIND_REQUIRED, fast_csv.ERROR_EMPTY),
        (b"1,2\n", fast_csv.KIND_REQUIRED, fast_csv.ERROR_TOO_MANY),
    ],
)
def test_bad_fields_stop_with_a_code(line, kind, error):
    buf = np.frombuffer(line, dtype=np.uint8)
    values = np.empty(1)
    result = fast_csv.parse_body(
        buf, 0, len(line), np.array([kind], np.int8), 0, 1, values, values.view(np.int64),
        np.zeros(1, np.uint8), np.zeros(1, np.int64), fast_csv.POW5_HIGH, fast_csv.POW5_LOW,
        fast_csv.EXACT_POWERS_OF_TEN)
    assert result[0] == 0
    assert result[1] == error
    assert result[2] == 0  # the byte offset of the bad line


def test_text_in_a_lenient_column_is_flagged_not_an_error():
    _, values, flags = parse_column(["1.5", "hello", "nan", "2"], fast_csv.KIND_LENIENT)
    assert flags.tolist() == [0, fast_csv.FLAG_TEXT, 0, 0]
    assert values[0] == 1.5 and np.isnan(values[1]) and np.isnan(values[2]) and values[3] == 2


def test_power_of_five_table_is_normalised():
    assert len(fast_csv.POW5_HIGH) == 308 + 342 + 1
    assert np.all(fast_csv.POW5_HIGH >> np.uint64(63) == 1)  # the top bit is always set
    # 5**0 is 1 shifted to the top of 128 bits.
    index = 342
    assert int(fast_csv.POW5_HIGH[index]) == 1 << 63 and int(fast_csv.POW5_LOW[index]) == 0
