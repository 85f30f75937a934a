"""The words a yes/no setting accepts, in one place (device URLs, filter parameters, the CLI)."""

from __future__ import annotations

TRUE_WORDS = frozenset({"1", "true", "yes", "on"})
FALSE_WORDS = frozenset({"0", "false", "no", "off"})
"""Compared after ``strip().lower()``."""


def flag_word(text: str) -> bool | None:
    """True or False for a yes/no word (:data:`TRUE_WORDS`, :data:`FALSE_WORDS`), else None."""
    word = text.strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    return None
