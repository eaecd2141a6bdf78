"""Where the answers are decided: every band, answer, verdict and selection of kraby-study.

Every statistic is over seeds: one value per complete seed (its final score, its AUC, ...).
docs/reference/statistics.md says what each one means and why it was chosen.

- [`comparison`][kraby_study.decision.comparison]: the best value and every other value's
  answer at the margin (best, equivalent, worse, undecided), one comparison per study that the
  verdict, the tables, the selection rules and campaigns read;
  [`robust`][kraby_study.decision.robust]: the tests of each interquartile-mean contrast those
  answers read.
- [`selection`][kraby_study.decision.selection]: the study's rule (``final_score``,
  ``fastest_equivalent``, ...) that picks the selected value from that comparison;
  [`front`][kraby_study.decision.front]: the same for a two-objective search's front;
  [`race`][kraby_study.decision.race]: which values a raced study drops, round by round.
- [`intervals`][kraby_study.decision.intervals]: the interval of a mean over seeds;
  [`measures`][kraby_study.decision.measures]: AUC, time to a threshold, repeatability,
  probability of improvement; [`verdict`][kraby_study.decision.verdict]: a sweep's verdict;
  [`failed_seeds`][kraby_study.decision.failed_seeds]: which seeds failed;
  [`coverage`][kraby_study.decision.coverage]: the measured coverage of the intervals at few
  seeds.

It reads numbers by value, never a database: the answers layer above gathers them from a store.
"""
