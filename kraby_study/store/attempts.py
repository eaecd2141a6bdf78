"""A new attempt of a trial that did not count: an interrupted one (what a requeue and Optuna's
heartbeat both queue) or a failed one queued again on purpose (``retry_failed``)."""

from __future__ import annotations

import optuna
from optuna.trial import FrozenTrial

from kraby_study.records.attributes import TrialAttrs


def requeue_stale(study: optuna.Study, trial: FrozenTrial) -> None:
    """Queue a fresh attempt of an interrupted trial; the later attempt supersedes it.

    Also Optuna's heartbeat callback, for trials whose owner stopped sending heartbeats.
    """
    queue_attempt(study, trial)


def queue_attempt(study: optuna.Study, trial: FrozenTrial, failed: str | None = None) -> None:
    """Queue a new attempt of ``trial`` with its key, seed and parameters (so the same run,
    with the same settings); ``failed``: the failure of a failed trial queued again on
    purpose, stored on the new attempt."""
    old = TrialAttrs.of(trial)
    attrs = TrialAttrs(key=old.key, seed=old.seed, retry_of=trial.number,
                       enqueued=old.enqueued, recheck_of=old.recheck_of,
                       retried_failure=failed)
    params = trial.params or trial.system_attrs.get("fixed_params", {})
    study.enqueue_trial(params=dict(params), user_attrs=attrs.stored())
