"""Device URL options declared as data, and the one parser that checks a query against them.

Every driver declares its options as a table of :class:`Option` records (name, type, default,
range or choices, unit, help); :func:`parse_options` validates a URL's query against the table
and gives every driver the same messages, ``URL: odr='fast' is not a number``. The tables also
answer ``inclinometer devices --options SCHEME`` and the GUI's device field
(:func:`option_rows`, :func:`format_options`).

Types: ``number`` (a finite float), ``integer`` (decimal, ``0x..`` or a whole float such as
``1e3``), ``flag`` (:data:`TRUE_WORDS` / :data:`FALSE_WORDS`), ``choice`` (one of
``choices``, numbers or words; ``aliases`` map other words onto them) and ``text``. An option
with its own ``parse`` (a ``fault=`` spec, a ``warmup=RISE:TAU``) takes the text itself and
raises :class:`ValueError` with the problem.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qsl

from app.core.words import FALSE_WORDS, TRUE_WORDS, flag_word
from drivers.errors import DeviceUrlError

__all__ = [
    "FALSE_WORDS", "TRUE_WORDS", "Option", "ParsedQuery", "flag_word", "format_options",
    "option_rows", "parse_options", "url_error",
]

TYPES = ("number", "integer", "flag", "choice", "text")


@dataclass(frozen=True, slots=True)
class Option:
    """One URL option of a driver.

    ``minimum``/``maximum`` bound a number or integer (inclusive); ``positive`` asks for more
    than 0. ``check`` returns a further problem of a typed value (``"is outside ..."``) or
    None; ``convert`` maps the checked value to what the driver keeps (an ODR to its label).
    ``field`` is the attribute of the driver's options record (default: ``name``).
    """

    name: str
    type: str
    default: object = None
    help: str = ""
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False
    choices: tuple[object, ...] = ()
    aliases: Mapping[str, object] = field(default_factory=dict)
    parse: Callable[[str], object] | None = None
    check: Callable[[Any], str | None] | None = None
    convert: Callable[[Any], object] | None = None
    field: str = ""
    repeatable: bool = False
    metavar: str = "..."

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f"option {self.name!r}: type {self.type!r} is not one of {TYPES}")

    @property
    def key(self) -> str:
        """The attribute this option sets on the driver's options record."""
        return self.field or self.name

    def limits(self) -> str:
        """The range or the choices, in words (``[0.1, 100]``, ``2, 4, 8, 16``), or ''."""
        if self.choices:
            return ", ".join(_choice_text(c) for c in self.choices)
        low = "0" if self.positive and self.minimum is None else _g(self.minimum)
        high = _g(self.maximum)
        if low is None and high is None:
            return "> 0" if self.positive else ""
        if high is None:
            return f"> {low}" if self.positive and self.minimum is None else f">= {low}"
        opening = "(" if self.positive and self.minimum is None else "["
        return f"{opening}{low or '-inf'}, {high}]"

    def read(self, text: str) -> object:
        """The value of ``text``; raises :class:`ValueError` with the problem (without the
        URL), ``odr='fast' is not a number``."""
        shown = f"{self.name}={_shown(text)}"
        value: object
        if self.parse is not None:
            try:
                value = self.parse(text)
            except ValueError as exc:  # a message that names the option stands as it is
                problem = str(exc)
                raise ValueError(problem if problem.startswith(self.name) else
                                 f"{shown}: {problem}") from None
        elif self.type == "flag":
            value = flag_word(text)
            if value is None:
                raise ValueError(f"{shown}: use 1 or 0 (also true/false, yes/no, on/off)")
        elif self.type == "text":
            value = text
        elif self.type == "choice":
            value = self._choice(text, shown)
        else:
            value = self._number(text, shown)
        if self.check is not None:
            issue = self.check(value)
            if issue is not None:
                raise ValueError(f"{shown} {issue}")
        return value if self.convert is None else self.convert(value)

    def _choice(self, text: str, shown: str) -> object:
        word = text.lower()
        if word in self.aliases:
            return self.aliases[word]
        for choice in self.choices:
            if isinstance(choice, str):
                if word == choice.lower():
                    return choice
            else:
                number = _to_number(text)
                if number is not None and number == choice:
                    return choice
        unit = f" ({self.unit})" if self.unit else ""
        raise ValueError(f"{shown} is not supported; use one of {self.limits()}{unit}")

    def _number(self, text: str, shown: str) -> float | int:
        value = _to_number(text)
        if value is None:
            kind = "whole number" if self.type == "integer" else "number"
            raise ValueError(f"{shown} is not a {'positive ' if self.positive else ''}{kind}")
        if not math.isfinite(value):
            raise ValueError(f"{shown} is not a finite number")
        unit = f" {self.unit}" if self.unit else ""
        if self.type == "integer" and value != int(value):
            raise ValueError(f"{shown}: expected a whole number {self._within()}".rstrip())
        if self.positive and not value > 0:
            raise ValueError(f"{shown} must be a positive number" +
                             (f" ({self.unit})" if self.unit else ""))
        low = -math.inf if self.minimum is None else self.minimum
        high = math.inf if self.maximum is None else self.maximum
        if not low <= value <= high:
            within = self._within()
            problem = f"is out of range{within[2:]}" if within.startswith("in ") else \
                f"must be {within}"
            raise ValueError(f"{shown} {problem}{unit}")
        return int(value) if self.type == "integer" else float(value)

    def _within(self) -> str:
        """``in [1, 10]``, ``>= 0`` (or '' without limits)."""
        limits = self.limits()
        return f"in {limits}" if limits[:1] in ("[", "(") else limits

    def row(self) -> dict[str, object]:
        """This option as plain data (JSON-ready): name, type, default, limits, unit, help."""
        return {"name": self.name, "type": self.type, "default": _jsonable(self.default),
                "limits": self.limits(), "minimum": _jsonable(_finite(self.minimum)),
                "maximum": _jsonable(_finite(self.maximum)), "positive": self.positive,
                "choices": [_jsonable(c) for c in self.choices], "unit": self.unit,
                "help": self.help, "repeatable": self.repeatable}


@dataclass(slots=True)
class ParsedQuery:
    """What :func:`parse_options` found: the values by :attr:`Option.key`, the texts of
    repeatable options, and the options the table does not know (when kept)."""

    values: dict[str, object]
    repeated: dict[str, list[object]]
    other: list[tuple[str, str]]


def url_error(url: str, message: str) -> DeviceUrlError:
    """The error for a bad device URL: ``URL: message`` (a long URL cut to 120 characters)."""
    shown = url if len(url) <= 120 else f"{url[:120]}... ({len(url)} chars)"
    return DeviceUrlError(f"{shown}: {message}")


def parse_options(
    url: str,
    query: str,
    table: Iterable[Option],
    *,
    overrides: Mapping[str, object] | None = None,
    keep_other: bool = False,
    context: str = "",
) -> ParsedQuery:
    """Check ``query`` (``odr=104&accel_fs=4``) against ``table``.

    Keys are case-insensitive; an option may be given once (unless ``repeatable``) and needs
    a value. ``overrides`` (name -> Python value, None removes) win over the query. Options
    not in the table are refused (``context`` is added to that message, `` for sim://static``)
    or, with ``keep_other``, returned in :attr:`ParsedQuery.other` as given.

    Raises
    ------
    DeviceUrlError
        With the URL and one line naming the option and the problem.
    """
    texts = _Texts(url, {option.name: option for option in table}, keep_other, context)
    for key, text in parse_qsl(query, keep_blank_values=True):
        texts.add(key.strip().lower(), text)
    for key, value in (overrides or {}).items():
        texts.override(key, value)
    return texts.parsed()


@dataclass(slots=True)
class _Texts:
    """The texts of a query, by option, before they are read (see :func:`parse_options`)."""

    url: str
    options: dict[str, Option]
    keep_other: bool
    context: str
    raw: dict[str, str] = field(default_factory=dict)
    repeated: dict[str, list[str]] = field(default_factory=dict)
    other: list[tuple[str, str]] = field(default_factory=list)

    def add(self, key: str, text: str) -> None:
        option = self.options.get(key)
        if option is not None and option.repeatable:
            self.repeated.setdefault(key, []).append(self._value(option, text.strip()))
        elif key in self.raw or any(key == seen for seen, _ in self.other):
            raise url_error(self.url, f"option {key!r} is given twice")
        elif option is not None:
            self.raw[key] = self._value(option, text.strip())
        elif self.keep_other:
            self.other.append((key, text))
        else:
            raise self._unknown(key)

    def override(self, key: str, value: object) -> None:
        option = self.options.get(key)
        if value is None:
            self.raw.pop(key, None)
        elif option is None and not self.keep_other:
            raise self._unknown(key)
        elif option is None:
            self.other = [(k, t) for k, t in self.other if k != key]
            self.other.append((key, _override_text(value)))
        elif option.repeatable:
            items = value if isinstance(value, list | tuple) else [value]
            self.repeated[key] = [self._value(option, _override_text(i)) for i in items]
        else:
            self.raw[key] = self._value(option, _override_text(value))

    def parsed(self) -> ParsedQuery:
        try:
            values = {self.options[k].key: self.options[k].read(t) for k, t in self.raw.items()}
            repeated = {self.options[k].key: [self.options[k].read(t) for t in texts]
                        for k, texts in self.repeated.items()}
        except ValueError as exc:
            raise url_error(self.url, str(exc)) from None
        return ParsedQuery(values, repeated, self.other)

    def _value(self, option: Option, text: str) -> str:
        if text == "":
            raise url_error(self.url, f"option {option.name!r} needs a value "
                                      f"({option.name}={option.metavar})")
        return text

    def _unknown(self, key: str) -> DeviceUrlError:
        allowed = ", ".join(self.options)
        return url_error(self.url, f"unknown option {key!r}{self.context}; allowed: {allowed}")


def option_rows(table: Iterable[Option]) -> list[dict[str, object]]:
    """The options as plain data (``devices --options SCHEME --json``)."""
    return [option.row() for option in table]


def format_options(table: Iterable[Option]) -> str:
    """The options as a text table: name, type, default, range or choices (with the unit),
    and help."""
    rows = [("option", "type", "default", "range / choices", "help")]
    for option in table:
        limits = option.limits()
        if option.unit and limits:
            limits = f"{limits} {option.unit}"
        elif option.unit:
            limits = option.unit
        kind = option.type + (" (repeatable)" if option.repeatable else "")
        rows.append((option.name, kind, _default_text(option.default), limits, option.help))
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    return "\n".join(
        "  ".join(cell.ljust(width) for cell, width in zip(row[:4], widths, strict=True))
        + "  " + row[4]
        for row in rows
    ).rstrip() + "\n"


# -- helpers ---------------------------------------------------------------------------------------
def _shown(text: str, limit: int = 40) -> str:
    """``text`` quoted for a message, cut to ``limit`` characters (a 400-digit number)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} chars)"


def _to_number(text: str) -> float | int | None:
    """A number from decimal, ``0x..``/``0o..``/``0b..`` or float text, else None."""
    try:
        number = int(text, 0)
    except ValueError:
        pass
    else:  # beyond 64 bits: a float (inf for 400 digits), as the range checks compare floats
        beyond = math.inf if number > 0 else -math.inf
        return number if abs(number) < 2**63 else _float(text, beyond)
    return _float(text, None)


def _float(text: str, otherwise: float | None) -> float | None:
    try:
        return float(text)
    except ValueError:
        return otherwise


def _override_text(value: object) -> str:
    return str(int(value)) if isinstance(value, bool) else str(value)


def _g(value: float | None) -> str | None:
    if value is None or (isinstance(value, float) and math.isinf(value)):
        return None
    return f"{value:g}"


def _finite(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def _choice_text(choice: object) -> str:
    return f"{choice:g}" if isinstance(choice, float) else str(choice)


def _jsonable(value: object) -> object:
    if isinstance(value, tuple | list):
        return [_jsonable(item) for item in value]
    try:
        json.dumps(value)
    except (TypeError, ValueError):
        return str(value)
    return value


def _default_text(value: object) -> str:
    if value is None or value == ():
        return "-"
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
