"""What a stored trial is: one record schema for the runner, ``list``, ``best`` and the report.

The lowest layer of kraby-study: it imports no database, Optuna or statistics code, so config and
plan may use it and stay pure. Optuna's trials are read here by their state's name.

Every study (a sweep, a search, a single training run) is an Optuna study. kraby-study adds:

- on the study, the attributes of [`StudyAttrs`][kraby_study.records.attributes.StudyAttrs] (what
  kind of study, how it was defined);
- on each trial, the attributes of [`TrialAttrs`][kraby_study.records.attributes.TrialAttrs] (its
  key, seed, settings and result);
- beside Optuna's tables, the learning curve of each trial (see `kraby_study.store`).

A planned run may take several attempts (a worker died, a command was stopped): the attempt that
counts is the latest one with the run's key ([`counted`][kraby_study.records.stored.counted]). A
trial's [`Outcome`][kraby_study.records.stored.Outcome] reads its Optuna state and failure reason;
an interrupted attempt is not a result. The rules here read a trial through
[`StoredTrial`][kraby_study.records.stored.StoredTrial]: Optuna's FrozenTrial, or the light row
``list`` reads straight from the tables (`kraby_study.store.rows`).
"""
