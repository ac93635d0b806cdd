"""Model-predictive control over the paper's four actions, one planner with a pluggable model.

* :mod:`pipeline.planning.params`: the ``planning`` section of ``params.yaml`` (no torch);
* :mod:`pipeline.planning.models`: what the planner predicts with (constant velocity with the
  robot's own motion applied exactly: ``cv-mpc``);
* :mod:`pipeline.planning.mpc`: the planner, and the greedy policy the evaluation runs.
"""
