"""Where the answers are decided: every band, answer, verdict and selection of kraby-study.

Every statistic is over seeds: one value per complete seed (its final score, its AUC, ...).
docs/reference/statistics.md says what each one means and why it was chosen.

- :mod:`comparison`: the best value and every other value's answer at the margin (best,
  equivalent, worse, undecided), one comparison per study that the verdict, the tables, the
  selection rules and campaigns read; :mod:`robust`: the tests of each interquartile-mean
  contrast those answers read.
- :mod:`selection`: the study's rule (``final_score``, ``fastest_equivalent``, ...) that picks
  the selected value from that comparison; :mod:`front`: the same for a two-objective search's
  front; :mod:`race`: which values a raced study drops, round by round.
- :mod:`intervals`: the interval of a mean over seeds; :mod:`measures`: AUC, time to a
  threshold, repeatability, probability of improvement; :mod:`verdict`: a sweep's verdict;
  :mod:`failed_seeds`: which seeds failed; :mod:`coverage`: the measured coverage of the
  intervals at few seeds.

It reads numbers by value, never a database: the answers layer above gathers them from a store.
"""
