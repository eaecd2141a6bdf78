"""The errors a command reports in one line, and how a line is made of any exception."""

from __future__ import annotations


class ConfigError(ValueError):
    """A configuration a user gave that cannot be run; its message is one line."""


class StoreError(RuntimeError):
    """The store cannot be used as asked; its message is one line."""


class DatabaseLost(RuntimeError):
    """The database stayed out of reach longer than the command was told to wait."""


class ClusterLost(RuntimeError):
    """The machines running the trials (a Ray cluster) stayed out of reach longer than the
    command was told to wait."""


def first_line(err: BaseException) -> str:
    """The first line of an exception's message (of the driver's error, for database errors);
    the exception's type name when the message is empty."""
    cause = getattr(err, "orig", None) or err
    text = str(cause).strip()
    return text.splitlines()[0] if text else type(cause).__name__
