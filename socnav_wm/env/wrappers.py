"""Gymnasium wrappers for what the project's DQN trainer adds on top of the environment, so
that any library agent can learn with the same help (``socnav_wm.agents.training`` calls the
same functions on its batched simulator).

* :class:`ProgressReward`: a learning-only reward per metre the robot gets closer to its goal,
  added to the environment's reward (SocNavGym's distance reward, paper_spec §3.2). The
  environment's own reward stays in ``info["env_reward"]``: report that one.
* :class:`NearestHumansFirst`: the observation's human blocks reordered nearest first (the
  simulator lists them in spawn order).

>>> import gymnasium as gym
>>> env = NearestHumansFirst(ProgressReward(gym.make("socnav_wm:SocNav-v0"), weight=1.0))
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

FEATURES_PER_HUMAN = 7


def goal_distance(obs: np.ndarray) -> np.ndarray:
    """Robot–goal centre distances (float64, one per observation row) in metres: the
    observation starts with the goal's position in the robot frame (paper_spec §2)."""
    obs = np.asarray(obs)
    return np.hypot(obs[..., 0], obs[..., 1]).astype(np.float64)


def progress_shaping(
    reward: np.ndarray | float,
    distance_before: np.ndarray | float,
    distance_after: np.ndarray | float,
    weight: float,
) -> np.ndarray | float:
    """``reward + weight · (distance before − distance after)``: the reward a learner sees."""
    return reward + weight * (distance_before - distance_after)


def nearest_first(obs: np.ndarray, features_per_human: int = FEATURES_PER_HUMAN) -> np.ndarray:
    """Observations (…, 2 + 7·H) with the human blocks ordered by robot–human distance, nearest
    first; ties keep spawn order (the same order as
    :func:`socnav_wm.agents.features.sort_humans_by_distance`)."""
    obs = np.asarray(obs)
    num_humans = (obs.shape[-1] - 2) // features_per_human
    if num_humans < 2:
        return obs
    humans = obs[..., 2:].reshape(*obs.shape[:-1], num_humans, features_per_human)
    distance_sq = np.square(humans[..., 0]) + np.square(humans[..., 1])
    order = np.argsort(distance_sq, axis=-1, kind="stable")
    humans = np.take_along_axis(humans, order[..., None], axis=-2)
    return np.concatenate([obs[..., :2], humans.reshape(*obs.shape[:-1], -1)], axis=-1)


class ProgressReward(gym.Wrapper):
    """Adds ``weight`` per metre of progress to the goal to the reward (see the module)."""

    def __init__(self, env: gym.Env, weight: float = 1.0) -> None:
        super().__init__(env)
        if not np.isfinite(weight) or weight < 0:
            raise ValueError(f"weight: must be a finite number >= 0, got {weight!r}")
        self.weight = float(weight)
        self._distance: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._distance = goal_distance(obs)
        return obs, info

    def step(self, action: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        if self._distance is None:
            raise RuntimeError("ProgressReward: call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(action)
        after = goal_distance(obs)
        shaped = progress_shaping(reward, self._distance, after, self.weight)
        self._distance = after
        return obs, float(shaped), terminated, truncated, {**info, "env_reward": reward}


class NearestHumansFirst(gym.ObservationWrapper):
    """The observation with its human blocks nearest first (see the module)."""

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return nearest_first(observation).astype(observation.dtype, copy=False)
