"""Use the simulator from gymnasium: the single env and the batched vector env.

    python examples/gym_env.py --episodes 20 --num-envs 256

The single env (``gym.make``) runs a hand-written policy that reads the 23-d observation: turn
towards the goal (its robot-frame position is the first two entries), then drive forward. The
vector env (``gym.make_vec``) steps ``--num-envs`` rooms at once with random actions, with
same-step autoreset. Needs only ``pip install .`` (the simulator's own dependencies).
"""

from __future__ import annotations

import argparse
import math

import gymnasium as gym
import numpy as np

import socnav_wm  # noqa: F401  (registers SocNav-v0; or gym.make("socnav_wm:SocNav-v0") alone)

STOP, FORWARD, LEFT, RIGHT = range(4)  # the paper's actions


def towards_goal(obs: np.ndarray) -> int:
    """Rotate until the goal is within about 10° of straight ahead, then go forward."""
    bearing = math.atan2(obs[1], obs[0])  # goal_y, goal_x in the robot frame (x forward)
    if abs(bearing) < 0.2:
        return FORWARD
    return LEFT if bearing > 0 else RIGHT


def single_env(episodes: int, seed: int) -> dict[str, int]:
    """Episodes ``0..episodes−1`` of ``seed`` with :func:`towards_goal`: outcome counts."""
    env = gym.make("SocNav-v0", human_policy="mixed")
    counts = {"success": 0, "human_collision": 0, "wall_collision": 0, "timeout": 0}
    for scenario in range(episodes):
        obs, info = env.reset(seed=seed, options={"scenario_id": scenario})
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(towards_goal(obs))
        if info["success"]:
            counts["success"] += 1
        elif info["collision"] != "none":  # "human" or "wall"
            counts[f"{info['collision']}_collision"] += 1
        else:
            counts["timeout"] += 1
    env.close()
    return counts


def vector_env(num_envs: int, steps: int, seed: int) -> int:
    """``steps`` random steps of ``num_envs`` rooms; the number of episodes that ended."""
    envs = gym.make_vec("SocNav-v0", num_envs=num_envs)
    envs.reset(seed=seed)
    rng = np.random.default_rng(seed)
    ended = 0
    for _ in range(steps):
        _, _, terminated, truncated, _ = envs.step(rng.integers(0, 4, size=num_envs))
        ended += int(np.sum(terminated | truncated))
    envs.close()
    return ended


def main(argv: list[str] | None = None) -> dict[str, int]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--steps", type=int, default=200, help="vector env steps")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    counts = single_env(args.episodes, args.seed)
    print(f"gym.make: towards-goal on {args.episodes} scenarios of seed {args.seed}: {counts}")
    ended = vector_env(args.num_envs, args.steps, args.seed)
    print(
        f"gym.make_vec: {args.num_envs} rooms x {args.steps} random steps, {ended} episodes ended"
    )
    return {**counts, "vector_episodes_ended": ended}


if __name__ == "__main__":
    main()
