"""Model-predictive control over the paper's four actions, one planner with a pluggable model.

* :mod:`pipeline.planning.params`: the ``planning`` section of ``params.yaml`` (no torch);
* :mod:`pipeline.planning.models`: the predictor interface, and constant velocity with the
  robot's own motion applied exactly (``cv-mpc``); ``wm-mpc`` plans with the planning world
  model of :mod:`pipeline.worldmodel.residual`;
* :mod:`pipeline.planning.vae_lstm`: the paper's VAE + LSTM as a predictor (``vae-lstm-mpc``);
* :mod:`pipeline.planning.oracle`: the simulator itself, cloned, as the ceiling (``oracle-mpc``);
* :mod:`pipeline.planning.mpc`: the planner, and the greedy policy the evaluation runs;
* :mod:`pipeline.planning.methods`: which files each planner reads, and its policy.
"""
