"""Database URLs: parsed, checked and shown without importing any database code.

Config validation and planning use this module and stay pure; opening a store is
[`kraby_study.store.store`][]'s job. URLs are SQLAlchemy's, ``dialect[+driver]://...``: a SQLite
file (``sqlite:///relative.db``, ``sqlite:////absolute.db``) or a PostgreSQL server
(``postgresql+psycopg://user:password@host:port/database``).
"""

from __future__ import annotations

import importlib.util
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from kraby_study.errors import ConfigError

POSTGRES_EXTRA = "pip install 'kraby-study[postgres]'"

_URL = re.compile(r"^(?P<backend>[A-Za-z0-9_]+)(?:\+(?P<driver>[A-Za-z0-9_]+))?://(?P<rest>.*)$",
                  re.DOTALL)
_POSTGRES_DRIVERS = {"psycopg": "psycopg", "psycopg2": "psycopg2", "pg8000": "pg8000",
                     "asyncpg": "asyncpg", "psycopg2cffi": "psycopg2cffi"}
"""PostgreSQL drivers SQLAlchemy knows -> the module each imports."""
_DEFAULT_POSTGRES_DRIVER = "psycopg"
"""The driver SQLAlchemy 2.1 takes for a plain postgresql:// URL."""


@dataclass(frozen=True)
class DatabaseUrl:
    """The parts of a database URL kraby-study needs."""

    backend: str
    """sqlite, postgresql, or another dialect's name."""
    driver: str | None
    """The driver named after ``+``, if any."""
    rest: str
    """Everything after ``://``."""

    @property
    def database(self) -> str | None:
        """The database part: a SQLite file's path, or a server's database name."""
        path = self.rest.split("?", 1)[0]
        if self.backend == "sqlite":
            # sqlite:///a.db -> "a.db", sqlite:////abs/a.db -> "/abs/a.db", sqlite:// -> None.
            return unquote(path[1:]) if path.startswith("/") and len(path) > 1 else None
        _, _, name = path.rpartition("/")
        return unquote(name) if "/" in path and name else None


def parse_url(url: str) -> DatabaseUrl:
    """The parts of a database URL.

    Raises:
        ConfigError: Not a database URL; one line.
    """
    match = _URL.match(str(url))
    if match is None:
        raise ConfigError(f"storage {url!r} is not a database URL (e.g. sqlite:///studies/"
                          "kraby.db or postgresql+psycopg://user@host/db)")
    return DatabaseUrl(backend=match["backend"].lower(), driver=match["driver"],
                       rest=match["rest"])


def check_url(url: str) -> None:
    """Refuse database URLs other than SQLite files and PostgreSQL servers with a driver.

    Raises:
        ConfigError: Not a URL, another database, an in-memory SQLite, or a PostgreSQL URL
            whose driver is not installed; one line.
    """
    parsed = parse_url(url)
    if parsed.backend not in ("sqlite", "postgresql"):
        raise ConfigError(f"storage {url!r}: only sqlite and postgresql databases are supported")
    if parsed.backend == "sqlite" and parsed.database in (None, ":memory:"):
        raise ConfigError(f"storage {url!r}: a SQLite store must be a file")
    if parsed.backend == "postgresql":
        driver = parsed.driver or _DEFAULT_POSTGRES_DRIVER
        module = _POSTGRES_DRIVERS.get(driver)
        if module is None or importlib.util.find_spec(module) is None:
            raise ConfigError(f"storage {shown_url(url)!r} needs the PostgreSQL driver {driver}, "
                              f"which is not installed: {POSTGRES_EXTRA} (and write the URL as "
                              "postgresql+psycopg://...)")


def sqlite_path(url: str) -> Path | None:
    """The file behind a SQLite URL, or None for other databases."""
    parsed = parse_url(url)
    if parsed.backend != "sqlite" or parsed.database is None:
        return None
    return Path(parsed.database)


def reading_url(url: str) -> str | None:
    """A URL that reads the database without creating or writing anything: a SQLite file
    opened read-only (None when there is no file yet), or the server itself."""
    path = sqlite_path(url)
    if path is None:
        return url
    if not path.exists():
        return None
    return f"sqlite:///file:{path}?mode=ro&uri=true"


def shown_url(url: str) -> str:
    """A database URL as commands and reports show it, any password hidden."""
    match = _URL.match(str(url))
    if match is None:
        return str(url)
    rest = match["rest"]
    netloc, slash, path = rest.partition("/")
    if "@" not in netloc:
        return str(url)
    userinfo, host = netloc.rsplit("@", 1)
    user, colon, _ = userinfo.partition(":")
    hidden = f"{user}:***" if colon else user
    prefix = str(url)[: len(str(url)) - len(rest)]
    return f"{prefix}{hidden}@{host}{slash}{path}"
