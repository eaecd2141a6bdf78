"""The plan types: TrialSpec (what a worker needs to run one trial, and nothing heavier to
import) and StudyPlan (a study laid out as specs, with its definition for the store)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

from kraby_study.records.attributes import StudyAttrs
from kraby_study.records.definition import (
    EVAL_EPISODES,
    EVAL_SET,
    SEEDING,
    UNRECORDED_EVAL_SET,
    UNRECORDED_SEEDING,
)

OPTIONAL_PPO: dict[str, Any] = {
    "learning_rate_schedule": "constant", "clip_range_schedule": "constant",
    "ortho_init": True, "log_std_init": 0.0, "use_sde": False, "sde_sample_freq": -1,
}
"""PPO settings a run's settings hold only where they differ from their defaults (those of
``config.schema.PPOConfig``, which are SB3's), so a study whose settings do not name them keeps its
fingerprint. Read them with [`ppo_setting`][kraby_study.plan.spec.ppo_setting]."""


def ppo_setting(ppo: dict[str, Any], name: str) -> Any:
    """A run's ppo setting, its [`OPTIONAL_PPO`][kraby_study.plan.spec.OPTIONAL_PPO] default when
    the settings leave it out."""
    return ppo[name] if name in ppo else OPTIONAL_PPO[name]


@dataclass(frozen=True)
class TrialSpec:
    """Everything one training run needs; a trial is a pure function of it."""

    study: str
    """Name of the study the run belongs to."""
    key: str
    """Identity of the run within its study, stable across reruns (e.g. 'v3-s2')."""
    seed: int
    """Seed of the policy, the sampler and every leg's resets."""
    steps: int
    """Environment steps to train for (exactly, to a multiple of n_envs)."""
    curve_every: int
    """Environment steps per learning-curve point."""
    settings: dict[str, Any]
    """Resolved env and ppo settings; ppo.batch_size is always a number here."""
    value: Any = None
    """Value of the swept setting."""
    model_path: str | None = None
    """Where to save the final model (SB3 zip), or None."""
    checkpoint_every: int | None = None
    """Report progress to a pruner every this many environment steps (searches only)."""
    seed_scores: bool = False
    """Report each seed's own score, the last seed's too, at the env steps of the seed's end,
    and nothing within a seed (searches with the wilcoxon pruner, which pairs seeds)."""
    seeds: int = 1
    """Training runs, with seeds seed, seed + 1, ...; the score is their mean (searches)."""
    seeding: str = SEEDING
    """How a run's seed gives each leg its random stream (`kraby_envs.seeding`): streams
    (independent children of the seed) or offset (seed + leg, before streams)."""
    objective: str = "final_reward"
    """final_reward (mean reward over the last 10 % of training) or evaluation."""
    cost: str | None = None
    """A two-objective search's cost (training_time): progress lines show it beside the
    score."""
    eval_episodes: int = EVAL_EPISODES
    """Evaluation episodes of the evaluation objective (the leg's targets, a gym env's seeded
    resets)."""
    eval_set: str = EVAL_SET
    """Where the evaluation episodes come from
    ([`EVAL_SETS`][kraby_study.records.definition.EVAL_SETS]): run, each seed's own (drawn from its
    evaluation stream), or fixed, one set shared by every run (a study whose definition has no
    ``eval_set``)."""
    label: str = ""
    """How progress lines name the run, e.g. 'clip_range=0.2 seed 1'."""
    tensorboard_run: str | None = None
    """Where SB3's TensorBoard logs go, as ``DIR/<study>/<name>``: seed n writes to
    ``<this>-seed<n>`` (``-attempt2``, ... added when an earlier attempt has that folder);
    None: no logs (``tensorboard_dir`` null)."""

    @property
    def reports(self) -> bool:
        """Whether the run reports intermediate values to a pruner (searches only)."""
        return bool(self.checkpoint_every) or self.seed_scores


@dataclass(frozen=True)
class RaceRules:
    """How a race runs: its settings (``racing.*`` and ``budget.seeds``)."""

    seeds: int
    """Most seeds any value gets."""
    round_seeds: tuple[int, ...] = ()
    """The seed of each round, first round first (``seed``, ``seed + 1``, ... in a sweep)."""
    min_seeds: int = 4
    """Seeds every value gets before the first look (a new race: at least
    [`ANSWER_FROM`][kraby_study.records.values.ANSWER_FROM]; a stored one may hold 3, whose first
    look answers nothing)."""
    alpha: float = 0.05
    """Family-wise error rate over every look of the race."""
    paired: bool = False
    """Each look compares values on their common seeds (seeds as blocks: the common seeds
    resampled together, Yuen's test for dependent trimmed means); False: each value's seeds
    apart, the report's own tests."""
    margin: float = 0.0
    """``compare.margin`` when the race began: a value shown within it of the look's best
    leaves as equivalent, one shown below the best by more than it as worse; 0: only values
    shown worse leave (races before margins)."""
    below: str = "cap"
    """A racing search's challenger with no answer and an IQM below the incumbent's on their
    common seeds leaves at the incumbent's seed count (``cap``) or at any look (``look``)."""

    @property
    def looks(self) -> int:
        """Rounds after which values can be dropped: min_seeds, ..., seeds."""
        return max(1, self.seeds - self.min_seeds + 1)

    @property
    def look_alpha(self) -> float:
        """The level of each look (alpha spent equally)."""
        return self.alpha / self.looks

    def describe(self) -> str:
        """How reports name the rule, e.g. 'racing from round 3 of 10, alpha 0.05 spent
        over 8 looks (0.00625 each)'."""
        test = ("the answers' step-down on the IQM, paired by seed (seeds as blocks)"
                if self.paired else "the answers' step-down on the IQM")
        leaves = (f"; a value leaves once shown worse by more than the margin ({self.margin:g} x "
                  "the look's best |IQM|) or shown equivalent to the best within it"
                  if self.margin > 0 else "")
        return (f"racing from round {self.min_seeds} of {self.seeds}: {test} at each look, "
                f"alpha {self.alpha:g} spent equally over {self.looks} looks "
                f"({self.look_alpha:.3g} each){leaves}")

    def stored(self) -> dict[str, float | int | bool | list[int]]:
        """The rules as a study's definition stores them: a race is never extended or mixed
        with a fixed design under one name (changing them would change past drops). An
        unpaired race stores no ``paired`` key, as every race did before pairing existed, and
        a race at margin 0 no ``margin`` key, so those resume unchanged; a race resumed at
        another margin is a changed definition, refused."""
        return {"seeds": self.seeds, "min_seeds": self.min_seeds, "alpha": self.alpha,
                "round_seeds": list(self.round_seeds), **({"paired": True} if self.paired else {}),
                **({"margin": self.margin} if self.margin > 0 else {}),
                **({"below": self.below} if self.below != "cap" else {})}

    @classmethod
    def of(cls, definition: dict[str, Any]) -> RaceRules | None:
        """The rules of a stored definition; None for a study that did not race."""
        stored = definition.get("racing")
        if not stored:
            return None
        return cls(seeds=int(stored["seeds"]),
                   round_seeds=tuple(int(s) for s in stored["round_seeds"]),
                   min_seeds=int(stored["min_seeds"]), alpha=float(stored["alpha"]),
                   paired=bool(stored.get("paired", False)),
                   margin=float(stored.get("margin", 0.0)),
                   below=str(stored.get("below", "cap")))


@dataclass(frozen=True)
class StudyPlan:
    """A study laid out (a sweep, a confirm study or a train run): its definition for the store and
    one spec per value and seed."""

    name: str
    parameter: str
    values: list[Any]
    specs: list[TrialSpec]
    definition: dict[str, Any]
    select: str | None = None
    """A sweep's selection rule (stored beside the definition, not in it)."""
    inputs: list[dict[str, Any]] = field(default_factory=list)
    """Settings taken from earlier studies' selected values (``Input.stored()``)."""
    campaign: dict[str, Any] | None = None
    """A campaign stage's place in its campaign (``Campaign.record``)."""
    racing: RaceRules | None = None
    """How its seeds race ([`kraby_study.decision.race`][]); None: every value gets every seed."""

    def notes(self) -> StudyAttrs:
        """What is stored beside the definition: rule, inputs, campaign."""
        return StudyAttrs(select=self.select, inputs=self.inputs or None,
                          campaign=self.campaign)

    @property
    def fingerprint(self) -> str:
        """Hash of the definition: the same study name must always mean the same sweep."""
        return fingerprint(self.definition)


def seeding_of(cfg: Any) -> str:
    """The seeding scheme a plan uses: ``seeding`` as the command settled it (the stored
    study's, or the one given), streams while unset."""
    return str(cfg.seeding) if cfg.seeding is not None else SEEDING


def evaluation_of(cfg: Any) -> tuple[str, int]:
    """The evaluation set and episodes a plan uses: ``search.eval_set`` and
    ``search.eval_episodes`` as the command settled them (the stored study's, or those
    given), a new study's defaults while unset."""
    search = cfg.search
    eval_set = str(search.eval_set) if search.eval_set is not None else EVAL_SET
    episodes = int(search.eval_episodes) if search.eval_episodes is not None else EVAL_EPISODES
    return eval_set, episodes


def with_evaluation(definition: dict[str, Any], eval_set: str) -> dict[str, Any]:
    """A definition as stored for ``eval_set``: run adds ``eval_set: run``; fixed adds
    nothing, so a study whose definition has no ``eval_set`` keeps its fingerprint and resumes on
    the set it began with."""
    return {**definition, "eval_set": eval_set} if eval_set != UNRECORDED_EVAL_SET \
        else dict(definition)


def with_seeding(definition: dict[str, Any], scheme: str) -> dict[str, Any]:
    """A definition as stored for ``scheme``: streams adds ``seeding: streams``; offset adds
    nothing, so every study defined before streams existed keeps its fingerprint and
    resumes, and an offset study defined today is that same study."""
    return {**definition, "seeding": scheme} if scheme != UNRECORDED_SEEDING else dict(definition)


def fingerprint(definition: dict[str, Any]) -> str:
    """A short stable hash of a JSON-able definition."""
    text = json.dumps(definition, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
