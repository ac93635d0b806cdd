"""Plan with a world model: the receding-horizon planner over the four actions.

    python examples/plan.py --episodes 20
    python examples/plan.py --episodes 20 --model models/planning/seed-0.pt

Without ``--model`` the planner predicts with constant velocity and the robot's own motion
(``ConstantVelocityModel``: the ``cv-mpc`` method of the evaluation). With ``--model`` it
predicts with a planning world model written by ``socnav-wm train-planning-model``
(``ResidualPlanningModel``: constant velocity plus the learned correction of each human's
velocity). Any object with the ``PlanningModel`` methods (``reset``, ``observe``, ``rollout``)
plugs in the same way. The planner's weights are ``params.yaml``'s ``planning`` section
(``PlanningParams``); the episodes are scenarios ``0..N−1`` of the test seed.
"""

from __future__ import annotations

import argparse

import numpy as np

from socnav_wm.config import EvalParams
from socnav_wm.env.params import EnvParams
from socnav_wm.env.rollout import run_episodes
from socnav_wm.planning.models import ConstantVelocityModel
from socnav_wm.planning.mpc import Planner
from socnav_wm.planning.params import PlanningParams


def main(argv: list[str] | None = None) -> dict[str, int]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", help="a planning model file (default: constant velocity)")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--horizon", type=int, default=PlanningParams().horizon)
    parser.add_argument("--prefix-length", type=int, default=PlanningParams().prefix_length)
    parser.add_argument("--scenario-seed", type=int, default=EvalParams().scenario_seed)
    args = parser.parse_args(argv)

    env_params = EnvParams()
    if args.model:
        from socnav_wm.planning.residual import ResidualPlanningModel
        from socnav_wm.worldmodel.planning_file import load_residual

        model = ResidualPlanningModel(load_residual(args.model, env_params), env_params)
    else:
        model = ConstantVelocityModel(env_params)
    params = PlanningParams(horizon=args.horizon, prefix_length=args.prefix_length)
    planner = Planner(model, params, env_params)
    # Every episode at once: the planner imagines episodes x candidates futures per step.
    episodes = run_episodes(
        env_params,
        planner.policy(),
        args.scenario_seed,
        np.arange(args.episodes),
        reads_simulator=planner.reads_simulator,  # the robot's pose, for the walls
    )
    counts = {"success": 0, "human_collision": 0, "wall_collision": 0, "timeout": 0}
    for episode in episodes:
        if episode.success:
            counts["success"] += 1
        elif episode.collision is not None:
            counts[f"{episode.collision}_collision"] += 1
        else:
            counts["timeout"] += 1
    print(
        f"{type(model).__name__}, {planner.num_candidates} candidates of {params.horizon} steps, "
        f"on {args.episodes} test scenarios: {counts}"
    )
    return counts


if __name__ == "__main__":
    main()
