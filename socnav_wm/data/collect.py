"""The ``collect`` stage: rollouts of the batched simulator into Parquet shards, under the
random policy or a planner's.

Episode ``i`` of the dataset is scenario ``i`` of the seed, and its random actions are a pure
function of ``(seed, i, t)`` too: the random policy's data does not depend on ``num_envs``, which
only trades memory for speed. Slots keep running new scenarios until ``episodes`` have been
handed out; each finished episode is copied out of the per-slot buffers and written whole (no
row ever spans two episodes, no episode spans two shards).

Under a planner (``planner``: the data a planning model meets when it plans, as DAgger and
iterative model-based RL collect it) each step takes the planner's action, or with probability
``epsilon`` (a coin keyed by ``(seed, i, t)``) the random one. A planner's policy serves
episodes that start together, so the slots run in waves of ``num_envs`` scenarios.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numba
import numpy as np

from socnav_wm.data.compatibility import made_with
from socnav_wm.data.shards import ShardWriter
from socnav_wm.env.core import NUM_ACTIONS, Simulator
from socnav_wm.env.draws import uniform
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_NONE

STREAM_RANDOM_POLICY = 100
"""Counter-based stream of the collector's actions (distinct from the simulator's streams)."""

STREAM_EXPLORE = 101
"""Counter-based stream of the coin that picks the random action under a planner."""

WRITE_EVERY_ROWS = 100_000
"""Finished episodes are buffered and handed to the Parquet writer in chunks of this size."""


@numba.njit(cache=True)
def random_actions(seed: int, scenario_id: np.ndarray, step: np.ndarray, out: np.ndarray) -> None:
    """Uniform actions in 0..3 keyed by (seed, scenario, step): independent of the batch."""
    for e in range(out.shape[0]):
        u = uniform(seed, scenario_id[e], STREAM_RANDOM_POLICY, step[e], 0, 0)
        out[e] = min(int(u * NUM_ACTIONS), NUM_ACTIONS - 1)


@numba.njit(cache=True)
def explore_coins(
    seed: int, scenario_id: np.ndarray, step: np.ndarray, epsilon: float, out: np.ndarray
) -> None:
    """Whether each env takes the random action at this step, probability ``epsilon``, keyed
    by (seed, scenario, step)."""
    for e in range(out.shape[0]):
        out[e] = uniform(seed, scenario_id[e], STREAM_EXPLORE, step[e], 0, 0) < epsilon


PlannerFactory = Callable[[], tuple[Callable[[Any], np.ndarray], bool]]
"""A fresh planner policy for episodes that start together, and whether it reads the simulator
(else the observations): what :mod:`socnav_wm.methods` builds."""


@dataclass(frozen=True)
class CollectSummary:
    episodes: int
    steps: int
    shards: list[Path]
    seconds: float
    success_rate: float
    human_collision_rate: float
    wall_collision_rate: float
    timeout_rate: float
    mean_episode_length: float

    def as_metrics(self) -> dict[str, float]:
        return {
            "episodes": self.episodes,
            "steps": self.steps,
            "shards": len(self.shards),
            "seconds": self.seconds,
            "steps_per_second": self.steps / self.seconds if self.seconds > 0 else float("nan"),
            "success_rate": self.success_rate,
            "human_collision_rate": self.human_collision_rate,
            "wall_collision_rate": self.wall_collision_rate,
            "timeout_rate": self.timeout_rate,
            "mean_episode_length": self.mean_episode_length,
        }


class _EpisodeBuffers:
    """Per-slot step buffers (num_envs, max_steps, …) and the finished episodes waiting."""

    def __init__(self, num_envs: int, max_steps: int, obs_dim: int, num_humans: int) -> None:
        shape = (num_envs, max_steps)
        self.obs = np.zeros((*shape, obs_dim), np.float32)
        self.action = np.zeros(shape, np.int8)
        self.reward = np.zeros(shape, np.float32)
        self.dmin = np.zeros(shape, np.float32)
        self.robot = np.zeros((*shape, 3), np.float32)
        self.human_xy = np.zeros((*shape, 2 * num_humans), np.float32)
        self.done: list[dict[str, np.ndarray]] = []
        self.done_rows = 0

    def finish(
        self, slot: int, episode_id: int, length: int, final_obs: np.ndarray, outcome: tuple
    ) -> None:
        success, collision, truncated = outcome
        t = np.arange(length, dtype=np.int32)
        obs = self.obs[slot, :length].copy()
        next_obs = np.empty_like(obs)
        next_obs[:-1] = obs[1:]
        next_obs[-1] = final_obs
        last = t == length - 1
        terminal = last & (success or collision != COLLISION_NONE)
        self.done.append(
            {
                "episode_id": np.full(length, episode_id, np.int64),
                "t": t,
                "obs": obs,
                "action": self.action[slot, :length].copy(),
                "reward": self.reward[slot, :length].copy(),
                "next_obs": next_obs,
                "is_first": t == 0,
                "is_last": last,
                "is_terminal": terminal,
                "truncated": last & truncated,
                "success": last & success,
                "collision": np.where(last, collision, COLLISION_NONE).astype(np.int8),
                "dmin": self.dmin[slot, :length].copy(),
                "robot_x": self.robot[slot, :length, 0].copy(),
                "robot_y": self.robot[slot, :length, 1].copy(),
                "robot_theta": self.robot[slot, :length, 2].copy(),
                "human_xy": self.human_xy[slot, :length].copy(),
            }
        )
        self.done_rows += length

    def drain(self) -> dict[str, np.ndarray]:
        columns = {key: np.concatenate([ep[key] for ep in self.done]) for key in self.done[0]}
        self.done, self.done_rows = [], 0
        return columns


def collect_rollouts(
    env_params: EnvParams,
    *,
    episodes: int,
    num_envs: int,
    seed: int,
    out_dir: str | Path,
    max_rows_per_shard: int,
    on_episodes: Callable[[int], None] | None = None,
    planner: PlannerFactory | None = None,
    epsilon: float = 0.0,
) -> CollectSummary:
    """Record ``episodes`` episodes (scenarios ``0..episodes−1`` of ``seed``) under the random
    policy or, given ``planner``, under its policy with a share ``epsilon`` of random actions.

    ``on_episodes(n)`` is called with the number of episodes finished since the last call
    (progress bars). Shards are written atomically; on an exception none of this run's shards
    is left looking complete.
    """
    if episodes < 1 or num_envs < 1:
        raise ValueError("episodes and num_envs must be >= 1")
    if not 0.0 <= epsilon <= 1.0:
        raise ValueError(f"epsilon: expected a probability in [0, 1], got {epsilon}")
    if env_params.num_observed_humans != env_params.num_humans or env_params.observed_obstacles:
        raise ValueError(
            "env.observed_humans, env.observed_obstacles: rollouts hold every human in spawn "
            "order and no obstacle (their schema); collect with the defaults"
        )
    start = time.perf_counter()
    num_envs = min(num_envs, episodes)
    sim = Simulator(num_envs, env_params)
    sim.reset(seed=seed)
    obs = sim.observation
    buffers = _EpisodeBuffers(num_envs, env_params.max_steps, sim.obs_dim, env_params.num_humans)
    actions = np.zeros(num_envs, np.int64)
    explore = np.zeros(num_envs, np.bool_)
    act, reads_simulator = planner() if planner is not None else (None, False)
    outcomes = np.zeros(4, np.int64)  # success, human, wall, timeout
    lengths = 0
    finished = 0
    with ShardWriter(
        out_dir, env_params.num_humans, max_rows_per_shard, env=made_with(env_params)
    ) as writer:
        while True:
            s = sim.state
            if s.done.all():  # a planner's next wave (the random policy hands out per slot)
                if planner is None or sim.next_scenario >= episodes:
                    break
                obs = sim.autoreset(np.arange(num_envs), limit=episodes - sim.next_scenario)
                act, reads_simulator = planner()
                continue
            running = np.flatnonzero(~s.done)
            t = s.step_count[running]
            random_actions(seed, s.scenario_id, s.step_count, actions)
            if act is not None:
                planned = np.asarray(act(sim if reads_simulator else obs), dtype=np.int64)
                explore_coins(seed, s.scenario_id, s.step_count, epsilon, explore)
                actions = np.where(explore, actions, planned)
            buffers.obs[running, t] = obs[running]
            buffers.action[running, t] = actions[running]
            result = sim.step(actions)
            buffers.reward[running, t] = result.reward[running]
            buffers.dmin[running, t] = result.info["dmin"][running]
            buffers.robot[running, t, :2] = s.robot_xy[running]
            buffers.robot[running, t, 2] = s.robot_theta[running]
            buffers.human_xy[running, t] = s.human_xy[running].reshape(len(running), -1)
            ended = np.flatnonzero(result.terminated | result.truncated)
            for slot in ended:
                collision = int(result.info["collision"][slot])
                outcome = (
                    bool(result.info["success"][slot]),
                    collision,
                    bool(result.truncated[slot]),
                )
                length = int(s.step_count[slot])
                buffers.finish(slot, int(s.scenario_id[slot]), length, result.obs[slot], outcome)
                outcomes += [outcome[0], collision == 1, collision == 2, outcome[2]]
                lengths += length
            finished += len(ended)
            if len(ended) and on_episodes is not None:
                on_episodes(len(ended))
            # Hand out new scenarios only while the dataset still needs episodes.
            if planner is None:
                obs = sim.autoreset(ended, limit=episodes - sim.next_scenario)
            else:
                obs = sim.observation
            if buffers.done_rows >= WRITE_EVERY_ROWS:
                writer.write(buffers.drain())
        if buffers.done:
            writer.write(buffers.drain())
        shards = writer.close()
    rates = outcomes / max(finished, 1)
    return CollectSummary(
        episodes=finished,
        steps=lengths,
        shards=shards,
        seconds=time.perf_counter() - start,
        success_rate=float(rates[0]),
        human_collision_rate=float(rates[1]),
        wall_collision_rate=float(rates[2]),
        timeout_rate=float(rates[3]),
        mean_episode_length=lengths / max(finished, 1),
    )
