"""What stored studies answer: the settings each selected, where each stands, what a campaign
ends with, the winners later studies take, and the configurations ``confirm`` retrains.

Reads the store ([`kraby_study.store`][]) and applies the selection rules
([`kraby_study.decision.selection`][]); the runner, the CLI and campaigns read answers from here.
"""
