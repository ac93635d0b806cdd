"""Model-predictive control over the paper's four actions, one planner with a pluggable model.

* :mod:`socnav_wm.planning.params`: the ``planning`` section of ``params.yaml`` (no torch);
* :mod:`socnav_wm.planning.models`: the predictor interface, and constant velocity with the
  robot's own motion applied exactly (``cv-mpc``); ``wm-mpc`` plans with the planning world
  model of :mod:`socnav_wm.worldmodel.residual` (:mod:`socnav_wm.planning.residual`);
* :mod:`socnav_wm.planning.vae_lstm`: the paper's VAE + LSTM as a predictor (``vae-lstm-mpc``);
* :mod:`socnav_wm.planning.oracle`: the simulator itself, cloned, as the ceiling (``oracle-mpc``);
* :mod:`socnav_wm.planning.mpc`: the planner, and the greedy policy the evaluation runs.

Which files each planner reads, and its policy by name: the registry, :mod:`socnav_wm.methods`.
"""
