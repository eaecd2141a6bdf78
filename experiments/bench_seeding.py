"""How much of the seed-to-seed spread the offset scheme hid (a measurement, not a test).

Reads two stores, each holding one configuration trained on the same seeds, once with
``seeding=offset`` (leg i of the run with seed s seeded with s + i, so runs s and s + 1 share
31 of 32 legs' episodes) and once with ``seeding=streams`` (every leg of every run its own
child of ``SeedSequence(s)``), and prints for each: n, mean and sd of the final score, the
correlation of the scores of runs s and s + k (Pearson, 95 % Fisher-z interval) for k = 1, 2,
4, 8 and 16, and the ratio of the two sample variances with its 95 % F interval and two tests
of equal variances (two-sided F, Brown-Forsythe). Under offset, the runs of one study share
episodes, so their spread leaves out what the episodes add; the ratio estimates that share.

The stores of docs/reference/statistics.md (Seeds), 30 seeds each at the quick budget::

    kraby-study confirm --baseline ppo=tuned --seeds 30 budget=quick seeding=offset \\
        confirm.seed=0 --storage sqlite:///seeding_offset.db save_models=false
    kraby-study confirm --baseline ppo=tuned --seeds 30 budget=quick seeding=streams \\
        confirm.seed=0 --storage sqlite:///seeding_streams.db save_models=false
    kraby-study confirm ... --seeds 60 confirm.seed=30 --storage sqlite:///seeding_offset_b.db
    kraby-study confirm ... --seeds 60 confirm.seed=30 --storage sqlite:///seeding_streams_b.db
    python experiments/bench_seeding.py \\
        --offset sqlite:///seeding_offset.db sqlite:///seeding_offset_b.db \\
        --streams sqlite:///seeding_streams.db sqlite:///seeding_streams_b.db
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import stats

from kraby_study.records.definition import seed_text, stored_seeding
from kraby_study.records.stored import Outcome, counted, outcome
from kraby_study.store.store import opened_for_reading

LAGS = (1, 2, 4, 8, 16)
LEVEL = 0.95


def seed_scores(urls: list[str], study: str | None) -> tuple[str, str, dict[int, float]]:
    """(study name, its seeding scheme, final score by seed) of the stores' one-value studies,
    their seeds pooled (each store one range of seeds of the same configuration)."""
    found = [store_scores(url, study) for url in urls]
    names, schemes = {f[0] for f in found}, {f[1] for f in found}
    if len(schemes) != 1:
        raise SystemExit(f"the stores {urls} seed by different schemes: {sorted(schemes)}")
    pooled: dict[int, float] = {}
    for _, _, by_seed in found:
        if pooled.keys() & by_seed.keys():
            raise SystemExit(f"the stores {urls} share seeds")
        pooled.update(by_seed)
    return "+".join(sorted(names)), schemes.pop(), pooled


def store_scores(url: str, study: str | None) -> tuple[str, str, dict[int, float]]:
    """(study name, its seeding scheme, final score by seed) of the store's one-value study."""
    with opened_for_reading(url) as store:
        names = [study] if study else store.study_names()
        if len(names) != 1:
            raise SystemExit(f"{url} holds {len(names)} studies; name one with --study")
        ledger = store.load(names[0])
        trials = [t for t in counted(ledger.trials()) if outcome(t) is Outcome.COMPLETE]
        values = {t.params.get("config") for t in trials}
        if len(values) != 1:
            raise SystemExit(f"{names[0]} holds {len(values)} configurations; one is needed")
        scheme = stored_seeding(ledger.attrs.definition)
        return names[0], scheme, {int(t.user_attrs["seed"]): float(t.value) for t in trials}


def lag_line(by_seed: dict[int, float], lag: int) -> str:
    """``lag k: r 0.41 [0.05, 0.67] (n 29 pairs)`` over the pairs of seeds k apart."""
    pairs = [(by_seed[s], by_seed[s + lag]) for s in sorted(by_seed) if s + lag in by_seed]
    if len(pairs) < 4:
        return f"lag {lag}: too few pairs ({len(pairs)})"
    x, y = np.array(pairs).T
    result = stats.pearsonr(x, y)
    low, high = result.confidence_interval(LEVEL)
    return (f"lag {lag:>2}: r {result.statistic:+.2f} [{low:+.2f}, {high:+.2f}] "
            f"(n {len(pairs)} pairs)")


def describe(label: str, name: str, scheme: str, by_seed: dict[int, float]) -> np.ndarray:
    scores = np.array([by_seed[s] for s in sorted(by_seed)])
    print(f"{label}: study {name}, seeding {scheme}, seeds {seed_text(by_seed)}: "
          f"mean {scores.mean():.5f}, sd {scores.std(ddof=1):.5f}")
    for lag in LAGS:
        print(f"  {lag_line(by_seed, lag)}")
    return scores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--offset", required=True, nargs="+", metavar="URL",
                        help="store URL(s) of the offset runs (seeds pooled)")
    parser.add_argument("--streams", required=True, nargs="+", metavar="URL",
                        help="store URL(s) of the streams runs (seeds pooled)")
    parser.add_argument("--study", default=None, help="study name (default: the only one)")
    args = parser.parse_args()
    offset = describe("offset ", *seed_scores(args.offset, args.study))
    streams = describe("streams", *seed_scores(args.streams, args.study))
    n, m = len(offset), len(streams)
    ratio = offset.var(ddof=1) / streams.var(ddof=1)
    # Var(offset)/Var(streams) ~ ratio_true * F(n - 1, m - 1) for normal scores.
    low = ratio / stats.f.ppf(1 - (1 - LEVEL) / 2, n - 1, m - 1)
    high = ratio / stats.f.ppf((1 - LEVEL) / 2, n - 1, m - 1)
    f_p = 2 * min(stats.f.cdf(ratio, n - 1, m - 1), stats.f.sf(ratio, n - 1, m - 1))
    bf = stats.levene(offset, streams, center="median")
    print(f"variance offset / streams: {ratio:.2f} [{low:.2f}, {high:.2f}] (95 % F interval, "
          f"normal scores); two-sided F test p {f_p:.3f}; Brown-Forsythe p {bf.pvalue:.3f}")
    print(f"share of the streams variance the offset runs show: {ratio:.0%}; hidden: "
          f"{max(0.0, 1 - ratio):.0%} (95 % interval of the hidden share "
          f"{max(0.0, 1 - high):.0%} to {max(0.0, 1 - low):.0%})")


if __name__ == "__main__":
    main()
