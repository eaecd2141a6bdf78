"""A new attempt of an interrupted trial: what a requeue and Optuna's heartbeat both queue."""

from __future__ import annotations

import optuna
from optuna.trial import FrozenTrial

from kraby_study.records.attributes import TrialAttrs


def requeue_stale(study: optuna.Study, trial: FrozenTrial) -> None:
    """Queue a fresh attempt of an interrupted trial; the later attempt supersedes it.

    Also Optuna's heartbeat callback, for trials whose owner stopped sending heartbeats.
    """
    old = TrialAttrs.of(trial)
    attrs = TrialAttrs(key=old.key, seed=old.seed, retry_of=trial.number,
                       enqueued=old.enqueued, recheck_of=old.recheck_of)
    params = trial.params or trial.system_attrs.get("fixed_params", {})
    study.enqueue_trial(params=dict(params), user_attrs=attrs.stored())
