"""Evaluation of every method on shared test scenarios, and the statistics of the report.

Modules: ``evaluate`` (running a method on the test scenarios, the evaluation files), ``stats``
(intervals, tests, Holm, Pareto front), ``comparisons`` (paired comparisons between methods,
Pareto analysis), ``paper`` (the paper's numbers and claims), ``claims`` (the claims checked
against this run), ``figures``, ``rendering`` (``summary.md`` and ``metrics/report.json``'s
content) and ``report`` (reads the evaluation and training files, writes the report).
"""
