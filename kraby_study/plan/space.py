"""A search's plan: the declared space, its checks, and how a trial's parameters set its config.

Pure: no training, no database and no Optuna (the space as Optuna distributions, the sampler
and the pruner are [`kraby_study.run.sampling`][]'s). The trials are asked for through the store.
"""

from __future__ import annotations

from typing import Any

from omegaconf import DictConfig

from kraby_study.config.validate import (
    RUN_LENGTH,
    rollout_size,
    to_container,
    validate_env,
    validate_ppo,
    validate_run_length,
)
from kraby_study.errors import ConfigError
from kraby_study.plan.racing import race_rules
from kraby_study.plan.settings import resolved_settings, with_value
from kraby_study.plan.spec import (
    OPTIONAL_PPO,
    RaceRules,
    evaluation_of,
    ppo_setting,
    seeding_of,
    with_evaluation,
    with_seeding,
)
from kraby_study.records.definition import REWARDS, check_objective, stored_objective
from kraby_study.records.values import value_key

SAMPLERS = ("tpe", "random", "nsga2", "gp")
PRUNERS = ("median", "hyperband", "wilcoxon", "none")
NMINIBATCHES = "ppo.nminibatches"
BATCH_SIZE = "ppo.batch_size"
"""A searched batch size at or above a trial's rollout means the whole rollout (batch_size
null), as rl-zoo3's settings mean it; below it, it must divide the rollout."""


def _fail(message: str) -> None:
    raise ConfigError(message)


def validate_search(cfg: DictConfig) -> None:
    """Refuse a search that cannot run: bad flags, a malformed space, a batch that cannot fit."""
    search = cfg.search
    if search.sampler not in SAMPLERS:
        _fail(f"unknown sampler {search.sampler!r}: choose {', '.join(SAMPLERS)}")
    if search.pruner is not None and search.pruner not in PRUNERS:
        _fail(f"unknown pruner {search.pruner!r}: choose {', '.join(PRUNERS)}")
    names = objectives(cfg)
    if racing(cfg):
        _validate_racing_search(cfg)
    if len(names) == 2 and search.pruner not in (None, "none"):
        _fail(f"Optuna cannot prune a trial with several objectives: search.objective="
              f"[{','.join(names)}] runs with --pruner none, not {search.pruner}")
    for name in ("trials", "checkpoints"):
        if int(search[name]) < 1:
            _fail(f"search.{name} must be at least 1, got {search[name]}")
    if search.cpu_budget is not None and not float(search.cpu_budget) > 0:
        _fail(f"search.cpu_budget must be a positive number of CPU seconds (or null), "
              f"got {search.cpu_budget}")
    _validate_trial_share(cfg)
    for name in ("startup_trials", "pruner_startup_trials"):
        if int(search[name]) < 0:
            _fail(f"search.{name} must be >= 0, got {search[name]}")
    if not 0 <= float(search.warmup) < 1:
        _fail(f"search.warmup must be in [0, 1) (a fraction of the first seed), "
              f"got {search.warmup}")
    _validate_recheck(cfg)
    if not 0 < float(search.wilcoxon_p) < 1:
        _fail(f"search.wilcoxon_p must be in (0, 1) (a p threshold), got {search.wilcoxon_p}")
    floor = search_floor(cfg)
    if floor is not None and floor not in [str(n) for n in search.enqueue[:int(search.trials)]]:
        _fail(f"search.floor={floor} is not an enqueued configuration: choose one of "
              f"search.enqueue ({', '.join(map(str, search.enqueue)) or 'empty'}) or null")
    if pruner_name(cfg) == "wilcoxon":
        _validate_wilcoxon(int(cfg.budget.seeds), float(search.wilcoxon_p))
    if not search.params:
        _fail("search.params is empty: the space needs at least one parameter")
    paths = [str(p.path) for p in search.params.values()]
    for path in dict.fromkeys(p for p in paths if paths.count(p) > 1):
        names = [str(n) for n, p in search.params.items() if str(p.path) == path]
        _fail(f"search.params: {' and '.join(names)} both set {path}: keep one")
    if NMINIBATCHES in paths and "ppo.batch_size" in paths:
        _fail("search both ppo.nminibatches and ppo.batch_size: choose one")
    for name, param in search.params.items():
        _validate_param(cfg, str(name), param)
    _validate_batches(cfg)
    _validate_run_lengths(cfg)


def _validate_trial_share(cfg: DictConfig) -> None:
    """A trial's share of the CPU budget: a fraction in (0, 1], with a budget to share, in a
    search whose trials report checkpoints (where the share is checked)."""
    share = cfg.search.get("trial_share")
    if share is None:
        return
    if not 0 < float(share) <= 1:
        _fail(f"search.trial_share must be in (0, 1] (a share of search.cpu_budget), got {share}")
    if search_cpu_budget(cfg) is None:
        _fail("search.trial_share is a share of search.cpu_budget: set --cpu-budget too")
    if len(objectives(cfg)) == 2 or pruner_name(cfg) == "wilcoxon":
        _fail("search.trial_share acts at a trial's checkpoints, which a two-objective search "
              "and the wilcoxon pruner do not report: leave it null there")


def search_trial_cap(cfg: DictConfig) -> float | None:
    """The CPU seconds one trial may be projected to use (``search.trial_share`` of
    ``search.cpu_budget``), or None for no cap."""
    share, budget = cfg.search.get("trial_share"), search_cpu_budget(cfg)
    return None if share is None or budget is None else float(share) * budget


def trial_cap_text(cfg: DictConfig) -> str:
    """The cap on one trial's CPU seconds as a search's lines name it after its pruner,
    ``, a trial projected past 300 CPU s stopped``; empty without one."""
    cap = search_trial_cap(cfg)
    return "" if cap is None else f", a trial projected past {cap:,.0f} CPU s stopped"


def objectives(cfg: DictConfig) -> list[str]:
    """The search's objective names, its reward first, then any cost
    ([`check_objective`][kraby_study.records.definition.check_objective]); ConfigError for a bad
    one."""
    objective = cfg.search.objective
    return check_objective(objective if isinstance(objective, str) else to_container(objective))


def pruner_name(cfg: DictConfig) -> str:
    """The search's pruner: ``search.pruner``, or when it is null, median with one objective
    and none with two (Optuna prunes no trial of several objectives), with the gp sampler
    (which learns nothing from a pruned trial) or in a racing search (its race stops
    configurations)."""
    if racing(cfg):
        return "none"
    if cfg.search.pruner is not None:
        return str(cfg.search.pruner)
    return "none" if len(objectives(cfg)) == 2 or cfg.search.sampler == "gp" else "median"


def racing(cfg: DictConfig) -> bool:
    """Whether the search races configurations over seeds (``racing.enabled``, ``--racing``)."""
    found = cfg.get("racing")
    return bool(found is not None and found.enabled)


def search_race_rules(cfg: DictConfig) -> RaceRules | None:
    """A racing search's rules: a configuration's looks from ``racing.min_seeds`` seeds on,
    alpha spent over them, ``compare.margin``, and ``budget.seeds`` the most seeds any
    configuration gets (the incumbent's cap); None for a search that does not race."""
    seeds = [int(cfg.seed) + i for i in range(int(cfg.budget.seeds))]
    return race_rules(cfg, seeds, "budget.seeds", search=True) if racing(cfg) else None


def racing_text(rules: RaceRules, sampler: str) -> str:
    """A racing search as its start line and dry run name it."""
    below = ("at any look (racing.below=look)" if rules.below == "look"
             else "at the incumbent's seed count")
    return (f"racing search: {sampler} sampler asks each challenger, which trains "
            f"{rules.min_seeds} seeds side by side, then one at a time against the incumbent; "
            f"it leaves once shown worse by more than compare.margin {rules.margin:g} (or "
            f"equivalent and not cheaper), replaces it once shown better (or equivalent and "
            f"cheaper in CPU s per run); alpha {rules.alpha:g} spent over {rules.looks} looks "
            f"({rules.look_alpha:.3g} each){', paired by seed' if rules.paired else ''}; "
            f"undecided, it leaves {below} if its IQM on the common seeds is not higher; the "
            f"incumbent earns a seed whenever no challenger wants one, up to {rules.seeds} "
            "(budget.seeds)")


def _validate_racing_search(cfg: DictConfig) -> None:
    """A racing search decides by its race: one objective, no pruner, no rechecks, no cap on
    one trial, a sampler that proposes one configuration at a time."""
    search = cfg.search
    if len(objectives(cfg)) == 2:
        _fail("--racing races one objective: drop the cost from search.objective")
    if search.pruner is not None and str(search.pruner) != "none":
        _fail(f"--racing stops configurations by its race: drop --pruner {search.pruner}")
    if int(search.recheck) > 0:
        _fail("--racing gives the incumbent its seeds itself: drop --recheck")
    if search.trial_share is not None:
        _fail("--racing stops configurations by its race: drop --trial-share")
    if str(search.sampler) == "nsga2":
        _fail("--racing asks one objective's sampler: choose --sampler tpe, gp or random")
    search_race_rules(cfg)


def method_text(cfg: DictConfig) -> str:
    """How a search chooses and stops its trials, as a dry run names it: the sampler, its seed
    and when its model takes over, the pruner ([`pruner_name`][kraby_study.plan.space.pruner_name])
    and any cap on one trial's CPU seconds, e.g. ``sampler tpe (search.seed 0; its model from trial
    5 on), pruner median``."""
    sampler = str(cfg.search.sampler)
    start = int(cfg.search.startup_trials)
    rules = search_race_rules(cfg)
    if rules is not None:
        return (f"sampler {sampler}{' multivariate' if sampler == 'tpe' else ''} (search.seed "
                f"{int(cfg.search.seed)}; its model after {start} configurations), no pruner; "
                + racing_text(rules, sampler))
    # The first trials are the enqueued ones, then random draws, until the model takes over.
    model = {"tpe": f"; its model from trial {start} on",
             "gp": f"; its model after {start} complete trials"}.get(sampler, "")
    return (f"sampler {sampler} (search.seed {int(cfg.search.seed)}{model}), "
            f"pruner {pruner_name(cfg)}{trial_cap_text(cfg)}")


def search_cpu_budget(cfg: DictConfig) -> float | None:
    """The CPU seconds a search may spend over all its trials (``search.cpu_budget``), or None
    for no limit but the trial total."""
    budget = cfg.search.get("cpu_budget")
    return None if budget is None else float(budget)


def recheck_plan(cfg: DictConfig) -> tuple[int, int]:
    """(leading trials rechecked, more seeds each) of a search (``search.recheck``,
    ``search.recheck_seeds``); (0, n) for none."""
    leaders, seeds = cfg.search.get("recheck"), cfg.search.get("recheck_seeds")
    return int(0 if leaders is None else leaders), int(2 if seeds is None else seeds)


def recheck_text(cfg: DictConfig) -> str:
    """A search's rechecks as its start line and its dry run name them; empty for none."""
    leaders, seeds = recheck_plan(cfg)
    if not leaders:
        return ""
    return (f"then its top {leaders} rechecked on {seeds} more seed(s) each, and the next in "
            "line for each that drops out")


def _validate_recheck(cfg: DictConfig) -> None:
    leaders, seeds = recheck_plan(cfg)
    if leaders < 0 or seeds < 1:
        _fail(f"search.recheck must be >= 0 and search.recheck_seeds >= 1, got "
              f"{leaders} and {seeds}")
    if leaders and len(objectives(cfg)) == 2:
        _fail("search.recheck needs one objective: a two-objective search's front is "
              "confirmed instead (kraby-study confirm --study-name NAME)")
    if leaders and pruner_name(cfg) == "wilcoxon":
        _fail("search.recheck with the wilcoxon pruner: it already races a trial's seeds; "
              "choose one (search.recheck=0 or another --pruner)")


def search_floor(cfg: DictConfig) -> str | None:
    """The search's floor: the enqueued ppo config whose score a two-objective search's trials
    must reach to be feasible (``search.floor``); None with one objective, which has none."""
    floor = cfg.search.get("floor")
    return str(floor) if floor is not None and len(objectives(cfg)) == 2 else None


def wilcoxon_seeds(p: float) -> int:
    """Finished seeds the wilcoxon pruner needs before it can stop a trial at threshold ``p``.

    The one-sided Wilcoxon signed-rank test of n paired seeds gives at best p = 1/2^n (every
    seed worse than the best trial's), so fewer than the least n with 1/2^n < p can never
    prune; Optuna's pruner also never prunes on fewer than 2 pairs. 0.1 needs 4.
    """
    n = 2
    while 0.5 ** n >= p:
        n += 1
    return n


def _validate_wilcoxon(seeds: int, p: float) -> None:
    """Refuse a wilcoxon search that could never stop a trial: the pruner may act after any
    seed but the last, so a trial needs ``wilcoxon_seeds(p) + 1`` seeds."""
    needed = wilcoxon_seeds(p)
    if seeds - 1 >= needed:
        return
    if seeds < 3:
        _fail(f"the wilcoxon pruner stops a trial's remaining seeds once at least 2 finished "
              f"ones are worse than the best trial's, and budget.seeds={seeds} never leaves "
              f"any to stop: give budget.seeds={needed + 1} or more (search.wilcoxon_p="
              f"{p:g}), or use --pruner median")
    least = f"1/2^{seeds - 1} = {0.5 ** (seeds - 1):.3g}"
    _fail(f"the wilcoxon pruner cannot stop a trial of budget.seeds={seeds} at "
          f"search.wilcoxon_p={p:g}: the signed-rank test on the {seeds - 1} seeds before the "
          f"last gives p >= {least}; give budget.seeds={needed + 1} or more, or "
          f"search.wilcoxon_p above {least}")


def _validate_param(cfg: DictConfig, name: str, param: DictConfig) -> None:
    where = f"search.params.{name}"
    if param.type in ("float", "int"):
        if param.low is None or param.high is None:
            _fail(f"{where}: a {param.type} range needs low and high")
        if param.low > param.high:
            _fail(f"{where}: low {param.low} is above high {param.high}")
        if param.log and param.low <= 0:
            _fail(f"{where}: a log range must start above 0, got low {param.low}")
        if param.type == "int" and (param.low != int(param.low) or param.high != int(param.high)):
            _fail(f"{where}: an int range needs whole-number bounds")
        samples = [param.low, param.high]
    elif param.type == "categorical":
        if not param.choices:
            _fail(f"{where}: a categorical parameter needs choices")
        choices = list(to_container(param.choices))
        if len({value_key(c) for c in choices}) != len(choices):
            _fail(f"{where}: a choice is listed twice")
        samples = choices
    else:
        _fail(f"{where}.type must be float, int or categorical, got {param.type!r}")
    if param.path == NMINIBATCHES:
        if any(not float(s).is_integer() or s < 1 for s in samples):
            _fail(f"{where}: nminibatches must be whole numbers >= 1")
        return
    if param.path == BATCH_SIZE:
        if any(not float(s).is_integer() or s < 2 for s in samples):
            _fail(f"{where}: batch sizes must be whole numbers >= 2")
        return
    for sample in samples:
        value = int(sample) if param.type == "int" else sample
        try:
            with_value(cfg, str(param.path), value)
        except ConfigError as err:
            _fail(f"{where}: {err}")


def _choices(cfg: DictConfig, path: str, default: Any) -> list[Any]:
    for param in cfg.search.params.values():
        if param.path == path:
            if param.type == "categorical":
                return list(to_container(param.choices))
            return list(range(int(param.low), int(param.high) + 1))
    return [default]


def _validate_batches(cfg: DictConfig) -> None:
    """Every sampled n_steps x n_envs rollout must split into the sampled minibatch counts, and
    every sampled batch size below a rollout must divide it."""
    sizes = _choices(cfg, BATCH_SIZE, None)
    if sizes != [None]:
        for n_steps in _choices(cfg, "ppo.n_steps", cfg.ppo.n_steps):
            for n_envs in _choices(cfg, "ppo.n_envs", cfg.ppo.n_envs):
                rollout = int(n_steps) * int(n_envs)
                for size in sizes:
                    if int(size) < rollout and rollout % int(size):
                        _fail(f"search.params: batch_size {size} does not divide the rollout "
                              f"{n_steps} x {n_envs} = {rollout}")
    counts = _choices(cfg, NMINIBATCHES, None)
    if counts == [None]:
        return
    for n_steps in _choices(cfg, "ppo.n_steps", cfg.ppo.n_steps):
        for n_envs in _choices(cfg, "ppo.n_envs", cfg.ppo.n_envs):
            rollout = int(n_steps) * int(n_envs)
            for count in counts:
                if rollout % int(count) or rollout // int(count) < 2:
                    _fail(f"search.params: nminibatches {count} does not split the rollout "
                          f"{n_steps} x {n_envs} = {rollout} into batches of at least 2")


def _validate_run_lengths(cfg: DictConfig) -> None:
    """Every trial the space allows can be scored by the search's reward: each n_envs and time
    limit it may sample, at the budget
    ([`validate_run_length`][kraby_study.config.validate.validate_run_length]).
    """
    env, ppo = to_container(cfg.env), to_container(cfg.ppo)
    paths = [str(param.path) for param in cfg.search.params.values()]
    searched = [path for path in RUN_LENGTH if path in paths]
    for n_envs in _choices(cfg, "ppo.n_envs", ppo["n_envs"]):
        for limit in _choices(cfg, "env.max_episode_steps", env.get("max_episode_steps")):
            values = {"ppo.n_envs": n_envs, "env.max_episode_steps": limit}
            where = ", ".join(f"{path}={values[path]}" for path in searched)
            validate_run_length({**env, "max_episode_steps": limit}, {**ppo, "n_envs": n_envs},
                                int(cfg.budget.steps), objectives(cfg)[0],
                                where=f"search.params, {where}: " if where else "")


def apply_params(cfg: DictConfig, params: dict[str, Any]) -> DictConfig:
    """The config of one trial: the sampled values set, the batch size made explicit."""
    trial_cfg = cfg
    minibatches = batch = None
    for name, value in params.items():
        path = str(cfg.search.params[name].path)
        if path == NMINIBATCHES:
            minibatches = int(value)
        elif path == BATCH_SIZE:
            batch = int(value)
        else:
            trial_cfg = with_value(trial_cfg, path, value)
    if minibatches is not None:
        trial_cfg = with_value(trial_cfg, "ppo.batch_size", rollout_size(trial_cfg.ppo)
                               // minibatches)
    if batch is not None:
        whole = batch >= rollout_size(trial_cfg.ppo)
        trial_cfg = with_value(trial_cfg, "ppo.batch_size", None if whole else batch)
    validate_env(trial_cfg.env, trial_cfg.ppo)
    validate_ppo(trial_cfg.ppo)
    return trial_cfg


def checkpoint_every(cfg: DictConfig) -> int:
    """Env steps between two intermediate values (the same for every trial)."""
    return max(1, int(cfg.budget.steps) // int(cfg.search.checkpoints))


def warmup_steps(cfg: DictConfig) -> int:
    """Env steps before the first checkpoint at which a pruner may stop a trial."""
    return max(checkpoint_every(cfg), int(float(cfg.search.warmup) * int(cfg.budget.steps)))


def search_definition(cfg: DictConfig) -> dict[str, Any]:
    """What must not change under a search's name (the trial total may)."""
    search = to_container(cfg.search)
    search.pop("trials")
    search.pop("name")
    search.pop("cpu_budget", None)  # when to stop, like the trial total: a search may extend
    # What a search does before it ends, not what its trials are: a stored search may be
    # rechecked later, and keeps the fingerprint it had before rechecks existed.
    search.pop("recheck", None)
    search.pop("recheck_seeds", None)
    # Stored resolved (the pruner's name, the objective as one name), so a one-objective
    # search's definition and fingerprint do not change with the defaults.
    search["pruner"] = pruner_name(cfg)
    search["objective"] = stored_objective(objectives(cfg))
    if search["pruner"] != "wilcoxon":
        # Read by the wilcoxon pruner only: other searches keep the definition (and the
        # fingerprint) they had before the setting existed.
        search.pop("wilcoxon_p", None)
    # Only a two-objective search with a floor stores one: others keep the definition (and
    # the fingerprint) they had before floors existed.
    search.pop("floor", None)
    # Likewise a share of the budget: stored only when set.
    if search.get("trial_share", 0) is None:
        search.pop("trial_share")
    floor = search_floor(cfg)
    if floor is not None:
        search["floor"] = floor
    eval_set, search["eval_episodes"] = evaluation_of(cfg)
    search.pop("eval_set", None)
    if objectives(cfg)[0] == REWARDS[1]:
        # Only an evaluation search stores where its episodes come from; a search stored
        # before they did (no key) evaluated every run on one fixed set.
        search = with_evaluation(search, eval_set)
    settings = resolved_settings(cfg)
    definition = {"kind": "search", "search": search, "settings": settings,
                  "steps": int(cfg.budget.steps), "seeds": int(cfg.budget.seeds),
                  "curve_every": int(cfg.budget.curve_every), "seed": int(cfg.seed)}
    rules = search_race_rules(cfg)
    if rules is not None:
        # A racing search is never resumed unraced, nor at other rules: its past moves would
        # change.
        definition["racing"] = rules.stored()
    return with_seeding(definition, seeding_of(cfg))


def _setting_values(cfg: DictConfig, settings: dict[str, Any]) -> dict[str, Any]:
    """Each space parameter's value in resolved settings (``nminibatches``: the rollout over the
    batch size, a fraction where it does not divide it); a parameter the settings lack (a
    leg's observation on a gym env) is left out."""
    values: dict[str, Any] = {}
    for name, p in cfg.search.params.items():
        root, leaf = str(p.path).split(".", 1)
        if str(p.path) in (NMINIBATCHES, BATCH_SIZE):
            ppo = settings["ppo"]
            rollout = int(ppo["n_steps"]) * int(ppo["n_envs"])
            batch = int(ppo["batch_size"])
            if str(p.path) == BATCH_SIZE:
                values[str(name)] = _batch_choice(p, batch, rollout)
            else:
                values[str(name)] = (rollout // batch if rollout % batch == 0
                                     else rollout / batch)
        elif leaf in settings.get(root, {}):
            values[str(name)] = settings[root][leaf]
        elif root == "ppo" and leaf in OPTIONAL_PPO:
            values[str(name)] = ppo_setting(settings["ppo"], leaf)  # left out at its default
    return values


def _batch_choice(param: DictConfig, batch: int, rollout: int) -> int:
    """The searched batch size that gives a resolved batch: itself below the rollout; for the
    whole rollout, the smallest choice at or above it (the batch itself when none is)."""
    if batch < rollout or param.type != "categorical":
        return batch
    above = sorted(int(c) for c in to_container(param.choices) if int(c) >= rollout)
    return above[0] if above else batch


def outside_space(cfg: DictConfig, settings: dict[str, Any]) -> dict[str, Any]:
    """The values of resolved settings that the search's space cannot hold (outside a range or
    the choices), by parameter: a known configuration enqueued first has these drawn by the
    sampler instead, so the search does not evaluate it as it is."""
    fitted = fitted_params(cfg, settings)
    return {name: value for name, value in _setting_values(cfg, settings).items()
            if name not in fitted}


def fitted_params(cfg: DictConfig, settings: dict[str, Any]) -> dict[str, Any]:
    """The space's parameters that resolved settings take, as far as the space holds them.

    A parameter whose value lies outside its range or choices is left out (the sampler draws
    it); ``nminibatches`` is read as the rollout over the batch size.
    """
    params: dict[str, Any] = {}
    values = _setting_values(cfg, settings)
    for name, p in cfg.search.params.items():
        if str(name) not in values:
            continue
        value = values[str(name)]
        if p.type == "categorical":
            match = [c for c in to_container(p.choices) if value_key(c) == value_key(value)]
            if match:
                params[str(name)] = match[0]
        elif isinstance(value, int | float) and not isinstance(value, bool) and (
                _bound(p, p.low) <= value <= _bound(p, p.high)):
            if p.type == "int" and float(value) != int(value):
                continue
            params[str(name)] = int(value) if p.type == "int" else float(value)
    return params


def _bound(param: DictConfig, bound: Any) -> int | float:
    """A range's bound as the sampler reads it (int ranges whole, float ranges as floats)."""
    return int(bound) if param.type == "int" else float(bound)
