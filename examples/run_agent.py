"""Load a trained agent and run it, greedy, step by step in the gymnasium env.

    python examples/run_agent.py models/agents/2stepahead-maspm/seed-0.pt --episodes 20

An agent file (written by ``socnav-wm train-agent``) holds the Q-network, the variant, its frozen
VAE and LSTM when it has them, and the scenario parameters it was trained on. ``agent.policy()``
is a greedy policy with its own world-model state: call it on an episode's first observation,
then once per step. The episodes are scenarios ``0..N−1`` of the test seed (``eval.scenario_seed``
of params.yaml), the ones ``socnav-wm evaluate`` runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

import gymnasium as gym

import socnav_wm  # noqa: F401  (registers SocNav-v0)
from socnav_wm.agents.agent_file import load_agent
from socnav_wm.config import EvalParams

SHIPPED = "models/agents/maspm/seed-0.pt"
"""One of the trained agents the repository ships."""


def _fail(message: str) -> NoReturn:
    """One line on stderr and exit status 2, as the socnav-wm commands do."""
    print(f"run_agent.py: error: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: list[str] | None = None) -> list[str]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "agent", nargs="?", help="an agent file, e.g. models/agents/dueling-dqn/seed-0.pt"
    )
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--scenario-seed", type=int, default=EvalParams().scenario_seed)
    parser.add_argument("--device", default="cpu", help="auto, cpu or cuda")
    args = parser.parse_args(argv)
    if args.agent is None:
        _fail(f"give an agent file, e.g. {SHIPPED} (`make models` lists them)")
    try:
        agent = load_agent(args.agent, args.device)
    except (ValueError, OSError) as exc:  # missing, unreadable or not an agent: one line
        _fail(str(exc).splitlines()[0])
    env_options = agent.env_params.to_dict()  # the scenarios the agent was trained on
    env = gym.make("SocNav-v0", **env_options)
    outcomes = []
    for scenario in range(args.episodes):
        obs, _ = env.reset(seed=args.scenario_seed, options={"scenario_id": scenario})
        act = agent.policy()  # a fresh world-model state for every episode
        terminated = truncated = False
        while not (terminated or truncated):
            action = int(act(obs[None])[0])  # the policy takes a batch of observations
            obs, _, terminated, truncated, info = env.step(action)
        if info["success"]:
            outcomes.append("success")
        elif info["collision"] != "none":
            outcomes.append(f"{info['collision']}_collision")
        else:
            outcomes.append("timeout")
    env.close()
    counts = {name: outcomes.count(name) for name in sorted(set(outcomes))}
    print(f"{agent.variant_name} ({args.agent}) on {args.episodes} test scenarios: {counts}")
    return outcomes


if __name__ == "__main__":
    main()
