"""``socnav-wm sweep``: studies, grids of agent runs (variants × seeds × parameter values) run
as Ray tasks (docs/studies.md, docs/cluster.md).

Modules, each layer importing only those above it in this list:

* ``params``: the ``studies`` section of ``params.yaml`` (:class:`StudyParams`);
* ``plan``: the grid (``--seeds``, ``--grid``), every run's parameters and fingerprint, the
  runs already finished (:class:`SweepPlan`), and a sweep's outcome (:class:`SweepResult`);
* ``claims``: the paper's claims a study checks (the horizon claim, the training claims);
* ``summary``: ``results.parquet``, ``summary.md``, ``claims.json`` and the figures;
* ``runner``: one run (train-agent, then evaluate) and the sweep on Ray.

The names below are imported lazily, so importing the package (the configuration imports
``socnav_wm.studies.params``) pays for nothing else; Ray is imported only when a sweep runs.
"""

from __future__ import annotations

from socnav_wm.exports import lazy_exports

_EXPORTS = {
    "GridValue": "socnav_wm.studies.params",
    "StudyParams": "socnav_wm.studies.params",
    "default_studies": "socnav_wm.studies.params",
    "RESULT_FILE": "socnav_wm.studies.plan",
    "RunSpec": "socnav_wm.studies.plan",
    "SweepPlan": "socnav_wm.studies.plan",
    "SweepResult": "socnav_wm.studies.plan",
    "named_study": "socnav_wm.studies.plan",
    "parse_grid": "socnav_wm.studies.plan",
    "parse_seeds": "socnav_wm.studies.plan",
    "plan_sweep": "socnav_wm.studies.plan",
    "run_sources": "socnav_wm.studies.plan",
    "study_from_options": "socnav_wm.studies.plan",
    "HORIZON_CLAIM": "socnav_wm.studies.claims",
    "TRAINING_CLAIMS_NOTE": "socnav_wm.studies.claims",
    "horizon_verdict": "socnav_wm.studies.claims",
    "training_claims": "socnav_wm.studies.claims",
    "SUMMARY_METRICS": "socnav_wm.studies.summary",
    "seed_interval": "socnav_wm.studies.summary",
    "write_results": "socnav_wm.studies.summary",
    "RunJob": "socnav_wm.studies.runner",
    "describe": "socnav_wm.studies.runner",
    "execute_run": "socnav_wm.studies.runner",
    "run_sweep": "socnav_wm.studies.runner",
}

__all__ = sorted(_EXPORTS)

__getattr__ = lazy_exports(__name__, _EXPORTS)
