"""The typed configuration schema Hydra composes into.

The dataclasses are registered in Hydra's ConfigStore, so a misspelt key or a value of the wrong
type fails while the config is composed; `kraby_study.config.validate` then refuses
impossible values before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class LegEnvConfig:
    """``env=leg``, the simulated leg: keyword arguments of ``kraby_envs.KrabyOneLegEnv``."""

    observation: str = "default"
    """Observation variant: default, with_tip, with_tip_to_target or sin_angles."""
    delta: float = 0.5
    """Size of the target box relative to the documented one (0..1)."""
    time_step: float = 0.05 / 12
    """Physics time step in seconds."""
    frameskip: int = 12
    """Physics sub-steps per environment step (control period = time_step x frameskip)."""
    max_episode_steps: int = 32
    """Episode length (a time limit, no terminal state)."""


@dataclass
class GymEnvConfig:
    """``env=gym``: any registered Gymnasium environment, by its id (docs/guide/environments.md)."""

    id: str = MISSING
    """The registered id, e.g. Pendulum-v1 (an id of a package of ``packages`` too)."""
    kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of ``gymnasium.make`` for this id (e.g. {g: 9.81})."""
    max_episode_steps: int | None = None
    """Time limit of an episode; null: the limit the id is registered with."""
    normalize: bool = False
    """Wrap the vectorised env in SB3's VecNormalize (running mean and variance of the
    observations, and of the returns when normalize_reward); its statistics are saved beside
    the model and used by evaluation. Curves and scores stay in the env's own reward units."""
    normalize_reward: bool = True
    """With normalize: also scale rewards for learning (VecNormalize's norm_reward)."""
    packages: list[str] = field(default_factory=list)
    """Python packages imported before the id is looked up: those that register ids of their
    own when imported (rl-zoo3's --gym-packages)."""


ENV_SCHEMAS = {"leg": LegEnvConfig, "gym": GymEnvConfig}
"""The env group's options and their schemas; ``conf/env/NAME.yaml`` builds on NAME's."""


@dataclass
class PPOConfig:
    """PPO settings in stable-baselines3's names."""

    n_envs: int = 32
    """Legs simulated side by side in one world."""
    n_steps: int = 128
    """Steps per leg per rollout; a rollout holds n_steps x n_envs transitions."""
    batch_size: int | None = None
    """Minibatch size; null means one minibatch of the whole rollout (nminibatches 1)."""
    n_epochs: int = 30
    """Passes over each rollout."""
    gamma: float = 0.9
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE bias-variance trade-off."""
    clip_range: float = 0.2
    """PPO clipping of the probability ratio."""
    ent_coef: float = 0.01
    """Entropy bonus weight."""
    vf_coef: float = 0.5
    """Value loss weight."""
    max_grad_norm: float = 0.5
    """Gradient clipping."""
    learning_rate: float = 1e-3
    """Adam step size (at the start, with learning_rate_schedule linear)."""
    learning_rate_schedule: str = "constant"
    """constant, or linear: from learning_rate down to 0 at the end of training (rl-zoo3's
    ``lin_0.001``)."""
    clip_range_schedule: str = "constant"
    """constant, or linear: clip_range down to 0 at the end of training (``lin_0.2``)."""
    net_arch: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of the policy and value networks (separate networks, same shape)."""
    activation: str = "tanh"
    """Hidden activation: tanh or relu."""
    ortho_init: bool = True
    """Orthogonal initialisation of the networks (SB3's default)."""
    log_std_init: float = 0.0
    """Initial log standard deviation of a continuous action's Gaussian."""
    use_sde: bool = False
    """Generalised state-dependent exploration (gSDE) instead of independent Gaussian noise;
    continuous (Box) actions only."""
    sde_sample_freq: int = -1
    """With use_sde: env steps between new noise matrices; -1: once per rollout."""


@dataclass
class StudyConfig:
    """A one-at-a-time sweep: one parameter, its values; the other settings come with the file."""

    name: str = MISSING
    """Name of the study in the store."""
    parameter: str = MISSING
    """Dotted path of the swept setting, e.g. ppo.ent_coef or env.observation."""
    values: list[Any] = MISSING
    """The values tried, in the order figures list them."""
    description: str = ""
    """What the study asks, shown by ``list`` and in reports."""
    select: str = "final_score"
    """How the study's value is selected once it is finished (the report's ``selected`` column,
    ``${winner:NAME}``, ``best``): final_score (highest mean final score), auc (highest mean
    AUC) or fastest_equivalent (lowest mean training time among the best and the values
    shown equivalent to it, within compare.margin). See docs/guide/campaigns.md."""


@dataclass
class BudgetConfig:
    """How much experience each training run gets."""

    name: str = "full"
    """Label of the budget."""
    steps: int = 250_000
    """Environment steps per training run (a run stops there, even inside a rollout)."""
    seeds: int = 10
    """Training runs (seeds) per value."""
    curve_every: int = 2048
    """Environment steps per learning-curve point."""


@dataclass
class ParamSpace:
    """The range of one searched setting."""

    path: str = MISSING
    """Dotted setting it sets (ppo.gamma, env.observation); ppo.nminibatches sets the batch size
    to n_steps x n_envs / nminibatches, so the batch always divides the rollout."""
    type: str = MISSING
    """float, int or categorical."""
    low: float | None = None
    """Lower bound (float and int)."""
    high: float | None = None
    """Upper bound, included (float and int)."""
    log: bool = False
    """Sample on a log scale (bounds must be > 0)."""
    choices: list[Any] | None = None
    """The values of a categorical parameter."""


@dataclass
class SearchConfig:
    """An Optuna search: the space, the sampler and pruner, and what is maximised."""

    name: str = "search"
    """Name of the study in the store."""
    trials: int = 50
    """Total trials of the study, over every invocation (a rerun tops it up to this number)."""
    cpu_budget: float | None = None
    """CPU seconds the search may spend, over every attempt of every trial and invocation:
    once its ended trials, what its running ones have used so far and what asking the sampler
    for each trial cost (its ``suggest_cpu``) reach them it asks for no new trial (those
    running finish, so it overshoots by what they use after that), so two searches compare at
    the same budget. null: no limit but ``trials``."""
    sampler: str = "tpe"
    """tpe, random, nsga2 (NSGA-II, Optuna's default population of 50) or gp (Optuna's
    Gaussian-process sampler, which models the score's noise; it learns from complete trials
    only). TPE and gp handle one objective or two."""
    pruner: str | None = None
    """median, hyperband, wilcoxon or none; null: median with one objective, none with two
    (Optuna prunes no trial of several objectives, and refuses a pruner there) or with the gp
    sampler (it learns nothing from a pruned trial). median and hyperband judge env-step
    checkpoints; wilcoxon races a trial's seeds: it sees each seed's final score and stops
    the remaining seeds once they are significantly worse than the best trial's same seeds."""
    seed: int = 0
    """Seed of the sampler, stored with the study."""
    startup_trials: int = 5
    """Trials sampled at random before TPE starts (for gp: complete trials)."""
    pruner_startup_trials: int = 3
    """Complete trials the median pruner waits for: it compares with their values."""
    recheck: int = 0
    """Leading trials retrained on ``recheck_seeds`` more seeds before the search ends, so its
    pick is judged on more seeds than it was found on: a trial ranks by the mean over all its
    seeds, and a trial that drops out of the top is replaced by the next, until the top
    ``recheck`` are all rechecked. Under a CPU budget the rechecks come out of it (exploring
    stops early enough to pay for them, and does not start again); once it is used, the best
    trial is still rechecked if it is not, so the pick is always a rechecked trial. 0: none.
    One objective only."""
    recheck_seeds: int = 2
    """More seeds a rechecked trial trains (after its own: seeds budget.seeds, ...)."""
    trial_share: float | None = None
    """With ``cpu_budget``: the share of it one trial may use. At each checkpoint a trial's
    CPU seconds so far and what it would still use at its own pace (to its last env step)
    are projected; a trial projected past ``trial_share * cpu_budget`` is stopped there and
    stored as pruned, with the projection as its ``cost_stop``. The configurations the search
    evaluates first (``enqueue``) and rechecks are never stopped for cost. It acts at the
    checkpoints, so not with two objectives or the wilcoxon pruner, which report none. null:
    no trial is stopped for its cost."""
    wilcoxon_p: float = 0.1
    """The wilcoxon pruner's p threshold: a trial's remaining seeds are stopped when the
    one-sided Wilcoxon signed-rank test of its finished seeds against the best trial's same
    seeds gives p below it. With n seeds p is at least 1/2^n, so 0.1 acts from the 4th seed
    on and needs budget.seeds >= 5 (see docs/benchmarks/index.md, Pruning)."""
    warmup: float = 0.5
    """Fraction of the first seed during which no trial is pruned: the first updates' reward
    says little about a configuration (it is mostly the untrained policy's). Not read by the
    wilcoxon pruner, which sees whole seeds only."""
    checkpoints: int = 4
    """Intervals of equal env steps in a trial's first seed; the mean reward of each but the
    last is an intermediate value (the pruner's steps), as is the mean score after each seed
    but the last. With the wilcoxon pruner the intermediate values are each seed's own score
    instead, at the env steps of the seed's end, and nothing within a seed."""
    objective: Any = "final_reward"
    """One reward, or a list of a reward and a cost ([final_reward,training_time]). Rewards
    (maximised): final_reward, the mean episode reward over the last 10 % of training;
    evaluation, the mean reward of the deterministic policy on a fixed set of targets (reset
    options). Cost (minimised): training_time, CPU seconds per seed (the worker's and its
    leg-stepping processes'), mean over the trial's seeds. Two objectives make a front of
    trials (docs/guide/studies.md)."""
    eval_episodes: int | None = None
    """Episodes of each run's evaluation (the evaluation objective, and a confirm of an
    evaluation search); null: a stored study's own number, 200 for a new one."""
    eval_set: str | None = None
    """Where a run's evaluation episodes come from: run (its own, drawn from its seed's
    evaluation stream, so a confirm's fresh seeds never meet its search's episodes) or fixed
    (one set every run shares); null: a stored study's own, run for a new one."""
    params: dict[str, ParamSpace] = field(default_factory=dict)
    """The space: Optuna parameter name -> range."""
    enqueue: list[str] | None = field(default_factory=lambda: ["tuned", "start"])
    """ppo config names whose settings are evaluated first, as far as the space holds them, so
    a search never ends below the settings it was given. null: a stored search's own, else the
    ppo config the command trains with (``optuna env=gym ppo=zoo`` starts from rl-zoo3's)."""
    floor: str | None = "tuned"
    """A two-objective search's floor: one of ``enqueue``. A trial scoring below the floor's
    measured score is infeasible: the sampler's good trials and the front leave it out, so the
    search looks for cheaper settings at least as good as the floor, not for cheap settings
    that learn little. null: no floor. Not read with one objective."""


@dataclass
class ReportConfig:
    """How ``report`` computes its statistics (see docs/reference/statistics.md)."""

    bootstrap: int = 2000
    """Bootstrap resamples of the bootstrap-t interval of a mean from 5 seeds on (final score,
    AUC, training time; seeded by the sample, so reproducible). Its coverage is measured at
    2000."""
    threshold: float | None = None
    """Reward a learning curve must reach for steps/seconds to threshold; null: 90 % of the way
    from the untrained policy's first-bin reward to the best value's final score."""
    min_seeds: int = 2
    """Fewest complete seeds a value needs to be answered (best, equivalent, worse, undecided),
    most sample-efficient, fastest or most repeatable (at least 2); values with fewer are listed
    as left out."""


@dataclass
class CompareConfig:
    """How values are compared with the best (see docs/reference/statistics.md, Four answers)."""

    margin: float = 0.2
    """The smallest difference in IQM final score that matters, as a fraction of the best
    value's |IQM| (0 .. 1): a value is equivalent when shown within it of the best, worse
    when shown below the best by more than it. 0: no value can be equivalent, and worse means
    shown worse at all. A race stores it; a report may
    re-analyse a finished study at any margin."""
    select: str | None = None
    """A selection rule that ``best``, ``report`` and ``${winner:...}`` apply instead of
    each study's stored one (re-selection without retraining); null: the study's own."""


@dataclass
class RacingConfig:
    """Racing a sweep's or a confirm study's seeds (see docs/guide/studies.md, Racing)."""

    enabled: bool = False
    """Run seeds in rounds: a value leaves once shown worse than the best (by more than
    compare.margin) or shown equivalent to it."""
    min_seeds: int = 4
    """Seeds every value gets before a value can be dropped (4 .. the most seeds: no answer is
    given below 4 seeds)."""
    alpha: float = 0.05
    """Family-wise error of every drop of the race together, in (0, 0.5]."""
    paired: bool = False
    """Compare values on the seeds they share (seeds as blocks) instead of each value's seeds
    apart; pays where a seed moves every value's score alike."""
    below: str = "cap"
    """A racing search's challenger with no answer yet and an IQM below the incumbent's on
    their common seeds leaves: at the incumbent's seed count (``cap``) or at any look
    (``look``, SMAC's rule, without the comparison's error control)."""


@dataclass
class ConfirmConfig:
    """What ``confirm`` retrains on fresh seeds (see the command's --help)."""

    study: str | None = None
    """The search or sweep whose top configurations are retrained; null: baselines only."""
    top: int = 5
    """Configurations retrained: the search's best complete trials (of a two-objective search,
    up to this many trials of its front, spread along it), or the sweep's best values."""
    seeds: int = 10
    """Fresh seeds per configuration, none used by the study's trials."""
    seed: int | None = None
    """First test seed: a confirm trains the first confirm.seeds seeds from here on that its
    source study did not use. null: 1000 for a new confirm study (apart from every tuning
    seed a command uses by default, 0 onwards), a stored confirm study's own first seed."""
    baselines: list[str] = field(default_factory=list)
    """ppo config names added as arms, e.g. [tuned]."""
    name: str | None = None
    """The confirm study's name in the store; null: NAME-confirm, or confirm-<baselines> when
    only baselines are retrained (two such confirms on two envs need a name each)."""
    select: str | None = None
    """The confirm study's selection rule (final_score, auc or fastest_equivalent, as a
    sweep's study.select); null: fastest_equivalent for a two-objective search's front,
    final_score otherwise. fastest_equivalent reads CPU seconds on a confirm study."""


@dataclass
class StageConfig:
    """One stage of a campaign: a study run after the earlier stages, with their winners."""

    study: str = MISSING
    """A study config name (conf/study/NAME.yaml or ./conf/study/NAME.yaml)."""
    select: str | None = None
    """The stage's selection rule; null: the study file's study.select."""
    documented: Any = None
    """The value the documented work chose, shown beside the selected one (null: none)."""


@dataclass
class CampaignConfig:
    """A chain of studies, each run with the values the earlier ones selected."""

    name: str = MISSING
    """Prefix of the stages' stored names: stage STUDY is stored as NAME-STUDY."""
    description: str = ""
    """What the campaign reproduces, shown in reports."""
    start: dict[str, Any] = field(default_factory=dict)
    """The settings the first stage starts from, as dotted keys (ppo.gamma: 0.9); they win over
    the study files' own settings."""
    stages: list[StageConfig] = MISSING
    """The stages, in the order they run."""


@dataclass
class RayConfig:
    """Where ``executor=ray`` runs trials (see docs/reference/architecture.md, Executors)."""

    address: str | None = None
    """null: start a Ray instance on this machine for the command; ``auto`` or ``host:port``:
    join a running cluster."""
    cpus_per_trial: int | None = None
    """CPUs each trial reserves on its node; null: the trial's shards (1 unless set)."""
    runtime_env: dict[str, Any] | None = None
    """Ray's runtime_env for the trials (e.g. {working_dir: ...}); null: every node has the
    project installed at the same path."""
    start_seconds: int = 300
    """How long an actor placed on a node may take to start (its process importing torch and
    the project) before it is taken as hung and its trial runs again. An actor waiting for a
    CPU does not count; one starting is alive, not silent. Measured (bench_actor_start.py):
    at most 4.8 s on a fresh interpreter, 14 s beside two training runs on 2 cores."""


@dataclass
class KrabyConfig:
    """Everything a command needs: composed from conf/config.yaml and the command line."""

    env: Any = MISSING
    """The environment: a [`LegEnvConfig`][LegEnvConfig] (env=leg) or a
    [`GymEnvConfig`][GymEnvConfig] (env=gym), typed by the option chosen."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    budget: BudgetConfig = field(default_factory=BudgetConfig)
    study: StudyConfig | None = None
    campaign: CampaignConfig | None = None
    search: SearchConfig = field(default_factory=SearchConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    confirm: ConfirmConfig = field(default_factory=ConfirmConfig)
    racing: RacingConfig = field(default_factory=RacingConfig)
    compare: CompareConfig = field(default_factory=CompareConfig)
    storage: str = "sqlite:///studies/kraby.db"
    """Database URL: a SQLite file (created on demand) or postgresql+psycopg://user@host/db."""
    executor: str = "local"
    """What runs the trials: local (worker processes on this machine) or ray (a Ray cluster);
    either way this command stays the only writer of the store."""
    ray: RayConfig = field(default_factory=RayConfig)
    workers: int | None = None
    """Trials at once; null: one per core (local), or the cluster's CPUs / ray.cpus_per_trial
    (ray)."""
    shards: int | None = None
    """Processes stepping each trial's legs, each a shard of them; null: the cores the workers
    leave (cores // workers). Results are the same for any number."""
    heartbeat_interval: int = 5
    """PostgreSQL: seconds between heartbeats of a running trial."""
    heartbeat_grace: int = 30
    """PostgreSQL: a running trial silent this long is failed and queued again."""
    db_retry_seconds: int = 60
    """How long a command keeps retrying a database it lost before it gives up."""
    retry_failed: bool = False
    """Queue the study's runs that failed with an error again (same key, seed and settings)
    before running: ``--retry-failed`` on run, optuna and confirm. Complete runs are left
    alone, and so are diverged ones (a divergence is a result of its settings)."""
    seed: int = 0
    """Seed of the first training run; run n of a study uses seed + n (a confirm's seeds are
    confirm.seed's)."""
    seeding: str | None = None
    """How a run's seed gives each of its n_envs legs a random stream: streams (leg i draws
    from child i of numpy's SeedSequence(seed): no two runs share a stream) or offset (leg i
    seeded with seed + i: runs s and s + 1 share all legs but one; the scheme before streams);
    null: a stored study's own scheme, streams for a new one."""
    save_models: bool = True
    """Keep each trial's final model (SB3 zip) beside the store."""
    models_dir: str | None = None
    """Where models go; null: a folder named after the SQLite file (else studies/models)."""
    out: str = "reports"
    """Output folder of ``report``."""
    tensorboard_dir: str | None = None
    """Folder of TensorBoard logs: each training run writes SB3's logs to
    DIR/<study>/<value or trial>-seed<n>; null: none (needs the [tensorboard] extra)."""


def register_schema() -> None:
    """Register the schema so conf/config.yaml can build on it (idempotent)."""
    cs = ConfigStore.instance()
    cs.store(name="kraby_schema", node=KrabyConfig)
    for name, schema in ENV_SCHEMAS.items():
        cs.store(group="env", name=f"{name}_schema", node=schema)
