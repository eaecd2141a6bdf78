"""What a stored campaign ends with: its stages as stored, and the settings its last stage
selected with every earlier winner."""

from __future__ import annotations

from typing import Any

from kraby_study.answers.selected import Selection, sweep_selection
from kraby_study.decision.comparison import CompareOptions
from kraby_study.errors import StoreError
from kraby_study.records.values import param_name, value_label
from kraby_study.store.store import Store


def campaign_selection(store: Store, name: str, options: CompareOptions | None = None
                       ) -> Selection:
    """The settings a finished campaign ends with: its last stage's selected value's, with the
    env settings any stage or the start set.

    Raises:
        StoreError: No stage of that campaign is stored, or a stage is not finished (the
            message names the first one and its progress).
    """
    stages = campaign_stages(store, name)
    if not stages:
        known = sorted({str(r["name"]) for r in campaign_records(store).values()})
        raise StoreError(f"no campaign {name!r} in {store.url}"
                         + (f" (campaigns: {', '.join(known)})" if known else ""))
    chosen = None
    for number, stage in enumerate(stages, start=1):
        done = None
        if stage["name"] in store.study_names():
            done = sweep_selection(store.load(str(stage["name"])), options)
        if done is None or not done.finished:
            progress = (f"{done.tally.complete}/{done.tally.planned} complete" if done is not None
                        else "not run yet")
            raise StoreError(f"campaign {name!r} is not finished: stage {number}/{len(stages)} "
                             f"{stage['name']} is {progress}; rerun the command that ran it "
                             f"(`kraby-study run campaign=FILE`, campaign.name {name})")
        chosen = done
    assert chosen is not None
    last = stages[-1]
    record = next(iter(campaign_records(store, name).values()))
    env_keys = sorted({str(s["parameter"]).split(".", 1)[1] for s in stages
                       if str(s["parameter"]).startswith("env.")}
                      | {key.split(".", 1)[1] for key in record.get("start", {})
                         if key.startswith("env.")})
    label = f"{param_name(str(last['parameter']))}={value_label(chosen.value)}"
    return Selection(short=f"campaign {name}: {label}",
                description=f"campaign {name!r} after its {len(stages)} stages (last: {label} "
                            f"in {last['name']}, mean final score {chosen.mean:.4g} over "
                            f"{len(chosen.trials)} seed(s), {chosen.rule}, margin "
                            f"{chosen.margin:.3g} in score units)",
                settings=chosen.trials[0].user_attrs.get("settings", {}), env_keys=env_keys,
                steps=chosen.trials[0].user_attrs.get("steps"))


def campaign_records(store: Store, name: str | None = None) -> dict[str, dict[str, Any]]:
    """Stored study name -> its campaign record, for every campaign stage (of ``name``),
    latest stage first."""
    records = {}
    for study in store.study_names():
        record = store.load(study).attrs.campaign
        if record and (name is None or record.get("name") == name):
            records[study] = record
    return dict(sorted(records.items(), key=lambda item: -int(item[1].get("stage", 0))))


def campaign_stages(store: Store, name: str) -> list[dict[str, Any]]:
    """The stages of a stored campaign, as its latest stored stage records them."""
    records = campaign_records(store, name)
    return list(next(iter(records.values()))["stages"]) if records else []
