"""``--param FILTER.NAME=VALUE``: the filter parameters ``replay`` and ``evaluate`` take."""

from __future__ import annotations

import argparse
from typing import Any

from app.core.filters import FILTERS
from app.core.words import FALSE_WORDS, TRUE_WORDS


def add_param_argument(parser: argparse.ArgumentParser) -> None:
    """Add the repeatable ``--param FILTER.NAME=VALUE`` option (``dest="params"``)."""
    parser.add_argument(
        "--param", dest="params", metavar="FILTER.NAME=VALUE", action="append", default=[],
        help="set a filter parameter, e.g. --param ekf.gyro_noise=2.5 (repeatable; checked "
             "against the filter's range; booleans take true/false/1/0)",
    )


def parse_filter_parameters(items: list[str] | None) -> dict[str, dict[str, Any]]:
    """``["ekf.gyro_noise=2.5", ...]`` -> ``{"ekf": {"gyro_noise": 2.5}}``, validated.

    Each value goes through the parameter's :class:`~app.core.filters.ParameterSpec` (type and
    range). Raises ValueError with a message for the user: bad form, unknown filter or
    parameter, a value out of range or not a number, a boolean that is not true/false/1/0.
    """
    found: dict[str, dict[str, Any]] = {}
    for item in items or []:
        target, equals, text = item.partition("=")
        filter_name, dot, name = target.strip().partition(".")
        text = text.strip()
        if not equals or not dot or not filter_name or not name or not text:
            raise ValueError(f"--param {item!r}: write FILTER.NAME=VALUE, e.g. "
                             "ekf.gyro_noise=2.5")
        cls = FILTERS.get(filter_name)
        if cls is None:
            raise ValueError(f"--param {item!r}: no filter {filter_name!r}; choose from "
                             f"{', '.join(FILTERS)}")
        try:
            spec = cls.parameter_spec(name)
        except KeyError:
            known = ", ".join(s.name for s in cls.parameters) or "none"
            raise ValueError(f"--param {item!r}: {filter_name} has no parameter {name!r} "
                             f"(it has: {known})") from None
        if spec.kind == "bool":
            word = text.lower()
            if word not in TRUE_WORDS | FALSE_WORDS:
                raise ValueError(f"--param {item!r}: {name} is true or false (or 1 or 0)")
            value: Any = word in TRUE_WORDS
        else:
            try:
                value = spec.validate(text)
            except ValueError as exc:
                raise ValueError(f"--param {item!r}: {exc}") from None
        found.setdefault(filter_name, {})[name] = value
    return found


def check_parameters_for(parameters: dict[str, dict[str, Any]], filters: list[str]) -> None:
    """Raise ValueError when ``--param`` names a filter that is not being run."""
    for name in parameters:
        if name not in filters:
            raise ValueError(f"--param {name}.NAME=...: the filter {name!r} is not among "
                             f"those run ({', '.join(filters)}); add it with --filter")
