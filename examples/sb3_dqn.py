"""Train a library agent on the environment: Stable-Baselines3's DQN with the project's wrappers.

    python examples/sb3_dqn.py --timesteps 200000 --test-episodes 500

The env is the registered gymnasium one (``socnav_wm:SocNav-v0``). ``ProgressReward`` adds the
learning-only progress reward the project's own trainer uses, ``NearestHumansFirst`` orders the
humans nearest first. The test runs the greedy policy on scenarios ``0..N−1`` of the project's
test seed (``eval.scenario_seed`` of params.yaml), the same scenarios as ``socnav-wm evaluate``,
and scores the environment's outcomes, not the shaped reward.

Needs ``pip install stable-baselines3`` (in the project's ``dev`` extra).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import torch
from stable_baselines3 import DQN

from socnav_wm.config import EvalParams
from socnav_wm.env.wrappers import NearestHumansFirst, ProgressReward


def make_env(progress_weight: float) -> gym.Env:
    return NearestHumansFirst(ProgressReward(gym.make("socnav_wm:SocNav-v0"), progress_weight))


def test(model: DQN, episodes: int, seed: int) -> dict[str, float]:
    """Greedy episodes on scenarios 0..episodes−1 of ``seed``: outcome rates."""
    env = make_env(0.0)
    outcomes = {"success": 0, "human_collision": 0, "wall_collision": 0, "timeout": 0}
    for scenario in range(episodes):
        obs, _ = env.reset(seed=seed, options={"scenario_id": scenario})
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(int(action))
            done = terminated or truncated
        if info["success"]:
            outcomes["success"] += 1
        elif truncated and not terminated:
            outcomes["timeout"] += 1
        else:
            outcomes[f"{info['collision']}_collision"] += 1
    return {k: v / episodes for k, v in outcomes.items()}


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=200_000, help="environment steps")
    parser.add_argument("--test-episodes", type=int, default=500)
    parser.add_argument("--progress-weight", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)

    start = time.process_time()
    model = DQN(
        "MlpPolicy",
        make_env(args.progress_weight),
        learning_rate=5e-4,
        buffer_size=100_000,
        learning_starts=min(5_000, args.timesteps // 2),
        batch_size=128,
        gamma=0.95,
        train_freq=1,
        target_update_interval=1_000,
        exploration_fraction=0.3,
        exploration_final_eps=0.05,
        policy_kwargs={"net_arch": [512, 128]},
        seed=args.seed,
        verbose=0,
    )
    model.learn(total_timesteps=args.timesteps)
    rates = test(model, args.test_episodes, EvalParams().scenario_seed)
    print(
        f"SB3 DQN, {args.timesteps:,} steps ({time.process_time() - start:.0f} CPU-s, 1 thread): "
        + ", ".join(f"{k} {v:.1%}" for k, v in rates.items())
        + f" on {args.test_episodes} test scenarios"
    )
    return rates


if __name__ == "__main__":
    main()
