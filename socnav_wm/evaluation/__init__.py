"""Evaluation of every method on shared test scenarios, and the statistics of the report.

Modules: ``params`` (the ``eval`` and ``report`` sections; no torch, no pyarrow), ``evaluate``
(running a method on the test scenarios, writing its files), ``records`` (the episodes and
trajectories tables, their files' metadata, their aggregation), ``results`` (the evaluation files
and training logs read back), ``intervals`` (confidence intervals), ``stats`` (paired tests,
Holm, Pareto front), ``comparisons`` (paired comparisons between methods, Pareto analysis),
``paper`` (the paper's numbers and claims), ``claims`` (the claims checked against this run),
``figures``, ``formatting`` (numbers and Markdown tables), ``rendering`` (``summary.md`` and
``metrics/report.json``'s content), ``model_sections`` (the summary's world-model and planning
sections) and ``report`` (reads the evaluation and training files, writes the report).
"""
