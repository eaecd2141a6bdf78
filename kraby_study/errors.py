"""One-line messages from exceptions whose text may span lines (or be empty)."""

from __future__ import annotations


def first_line(err: BaseException) -> str:
    """The first line of an exception's message (of the driver's error, for database errors);
    the exception's type name when the message is empty."""
    cause = getattr(err, "orig", None) or err
    text = str(cause).strip()
    return text.splitlines()[0] if text else type(cause).__name__
