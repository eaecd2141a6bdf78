"""The store keeps what it holds apart: a study deleted with Optuna's own tools leaves no
learning curve that a later study's trials would read as theirs."""

from __future__ import annotations

from pathlib import Path

import optuna
from conftest import sqlite_url
from synthetic import Run, add_sweep

from kraby_study.records.stored import Outcome
from kraby_study.store.store import opened


def test_a_study_deleted_with_optuna_leaves_no_curve_to_a_later_one(workdir: Path) -> None:
    url = sqlite_url(workdir / "k.db")
    curve = [(100, -0.5, 1.0), (200, -0.2, 2.0)]
    with opened(url) as store:
        add_sweep(store, "kept", "ppo.gamma", [0.9],
                  [Run(value=0.9, seed=0, final_score=-0.1, curve=curve)], steps=200,
                  curve_every=100)
        add_sweep(store, "gone", "ppo.gamma", [0.9, 0.99],
                  [Run(value=v, seed=0, final_score=-0.2, curve=curve) for v in (0.9, 0.99)],
                  steps=200, curve_every=100)
        gone_ids = {t._trial_id for t in store.load("gone").trials()}
    optuna.delete_study(study_name="gone", storage=url)
    with opened(url) as store:
        later = add_sweep(store, "later", "ppo.gamma", [0.9, 0.99],
                          [Run(value=v, seed=0, outcome=Outcome.PENDING) for v in (0.9, 0.99)])
        # SQLite gave the later study's trials the deleted ones' ids ...
        assert {t._trial_id for t in later.trials()} == gone_ids
        # ... and none of them reads a curve it never drew; the kept study's curve is whole.
        assert later.curves().empty
        assert len(store.load("kept").curves()) == len(curve)
