"""A study store opened by URL: the studies it holds, each study's runs and answers.

Each call reads the store afresh and closes it, so a notebook sees what a command running
elsewhere has written since; nothing here writes. Listing the studies reads no Optuna.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from kraby_study.api.answers import (
    Answers,
    Runs,
    StudyInfo,
    read_answers,
    read_runs,
    read_studies,
)
from kraby_study.config.storage import DEFAULT_STORAGE

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class StudyStore:
    """The studies of one store (SQLite file or PostgreSQL database), read-only.

    Attributes:
        url: The store's database URL.
    """

    url: str

    def studies(self) -> list[StudyInfo]:
        """Every study in the store with its progress, in the order Optuna lists them.

        Raises:
            StoreError: No store at the URL, or it cannot be read; one line.
        """
        return read_studies(self.url)

    def studies_frame(self) -> pd.DataFrame:
        """`studies` as a frame, one row per study.

        Examples:
            >>> import kraby_study as ks
            >>> list(ks.open_store("sqlite:///example.db").studies_frame()["name"])[:1]
            ['clip_range']
        """
        import pandas as pd

        return pd.DataFrame([asdict(s) for s in self.studies()],
                            columns=list(StudyInfo.__dataclass_fields__))

    def runs(self, study: str) -> Runs:
        """A study's counted runs (a sweep's value x seed, a search's trials).

        Raises:
            StoreError: No store, or no study of that name; one line.

        Examples:
            >>> import kraby_study as ks
            >>> runs = ks.open_store("sqlite:///example.db").runs("clip_range")
            >>> len(runs), sorted({run.value for run in runs})
            (4, ['0.1', '0.2'])
        """
        return read_runs(self.url, study)

    def answers(self, study: str, margin: float | None = None, select: str | None = None,
                min_seeds: int = 2) -> Answers:
        """A sweep's (or confirm study's) answers: each value best, equivalent, worse or
        undecided against the best, and the value its rule selects.

        Args:
            study: The stored study's name.
            margin: The margin as a fraction of the best's |IQM| (default 0.2).
            select: A selection rule to apply instead of the study's stored one.
            min_seeds: The fewest complete seeds a value needs to be compared.

        Raises:
            StoreError: No store, no study of that name, or a search; one line.

        Examples:
            >>> import kraby_study as ks
            >>> found = ks.open_store("sqlite:///example.db").answers("clip_range")
            >>> found.parameter, [v.seeds for v in found.values]
            ('ppo.clip_range', [2, 2])
        """
        return read_answers(self.url, study, margin, select, min_seeds)


def open_store(url: str = DEFAULT_STORAGE) -> StudyStore:
    """Open a study store by its database URL, to read its studies.

    Args:
        url: ``sqlite:///PATH`` or a PostgreSQL URL (default: the commands' default store).

    Returns:
        The `StudyStore`; nothing is read until one of its methods is called.

    Raises:
        ConfigError: The URL is not a supported database URL; one line.

    Examples:
        >>> import kraby_study as ks
        >>> store = ks.open_store("sqlite:///example.db")
        >>> [s.name for s in store.studies()][:1]
        ['clip_range']
    """
    from kraby_study.store.url import check_url

    check_url(url)
    return StudyStore(url)
