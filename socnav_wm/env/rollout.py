"""Run a policy in the batched simulator and record what happened, step by step.

Used by ``socnav-wm render`` (frames of a few episodes), by the evaluation, and by anything that
needs whole trajectories (metrics, GIFs). Policies are callables from observations
``(N, obs_dim)`` to actions ``(N,)`` (or ``(N, 2)`` continuous commands); a controller that reads
the simulator's world-frame state instead (the ORCA and SFM baselines) is passed with
``reads_simulator=True`` and is called with the simulator itself. The recorder never resets a
slot, so slot ``i`` holds scenario ``scenario_ids[i]`` from start to end.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from socnav_wm.env.core import NUM_ACTIONS, Simulator
from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_NAMES

Policy = Callable[[np.ndarray], np.ndarray]
"""Observations (N, obs_dim) → actions (N,) int or commands (N, 2) float."""

SimulatorPolicy = Callable[[Simulator], np.ndarray]
"""The simulator (read-only use: ``sim.state``, ``sim.params``) → actions or commands."""


def random_policy(seed: int) -> Policy:
    """Uniform over the 4 discrete actions, from its own seeded generator."""
    rng = np.random.default_rng(seed)

    def act(obs: np.ndarray) -> np.ndarray:
        return rng.integers(0, NUM_ACTIONS, size=obs.shape[0])

    return act


def run_episodes(
    params: EnvParams,
    policy: Policy | SimulatorPolicy,
    seed: int,
    scenario_ids: np.ndarray,
    *,
    reads_simulator: bool = False,
) -> list[Episode]:
    """Run scenarios ``scenario_ids`` of ``seed`` to their end, all at once in one batch.

    Args:
        params: the scenario parameters.
        policy: ``policy(obs)`` (default) or, with ``reads_simulator``, ``policy(sim)``; called
            once per step for the whole batch (finished slots included, their actions ignored).
        seed: the scenario seed; scenario ``i`` of a seed is the same whatever else runs.
        scenario_ids: (N,) the scenarios, one per slot.
        reads_simulator: pass the simulator instead of the observations, for controllers that
            read the world-frame state (``lambda sim: baseline.act(sim.state, sim.params)``).
    """
    ids = np.asarray(scenario_ids, dtype=np.int64)
    sim = Simulator(len(ids), params)
    obs, info = sim.reset(seed=seed, scenario_ids=ids)
    info["human_theta"] = sim.state.human_theta()
    groups = sim.state.human_group.copy()
    # Static obstacles (fixed for the whole episode); none recorded when the scenario has none.
    obstacles = params.max_obstacles > 0
    obstacle_kind = sim.state.obstacle_kind.copy()
    obstacle_xy = sim.state.obstacle_xy.copy()
    obstacle_half = sim.state.obstacle_half.copy()
    frames = [info]
    steps = []
    commands = []
    while not sim.state.done.all():
        observed = sim if reads_simulator else obs
        actions = np.asarray(policy(observed))  # type: ignore[arg-type]
        # What the robot will execute (the same lookup/clipping sim.step applies).
        commands.append(np.stack(sim.commands(actions), axis=-1))
        result = sim.step(actions)
        obs = result.obs
        result.info["human_theta"] = sim.state.human_theta()
        frames.append(result.info)
        steps.append((actions, result))
    # Stack each quantity once over time, (T+1, N, …) or (T, N, …), then slice per env: a
    # per-env loop over the steps would cost O(N·T) Python operations.
    robot_xy = np.stack([f["robot_xy"] for f in frames])
    robot_theta = np.stack([f["robot_theta"] for f in frames])
    human_xy = np.stack([f["human_xy"] for f in frames])
    human_theta = np.stack([f["human_theta"] for f in frames])
    actions = np.stack([a for a, _ in steps])
    rewards = np.stack([r.reward for _, r in steps])
    dmin = np.stack([r.info["dmin"] for _, r in steps])
    executed = np.stack(commands)
    episodes = []
    for e, scenario in enumerate(ids):
        last = int(sim.state.step_count[e])  # steps this episode took
        end = steps[last - 1][1]
        collision = int(end.info["collision"][e])
        episodes.append(
            Episode(
                scenario_id=int(scenario),
                robot_xy=robot_xy[: last + 1, e].copy(),
                robot_theta=robot_theta[: last + 1, e].copy(),
                goal_xy=frames[0]["goal_xy"][e].copy(),
                human_xy=human_xy[: last + 1, e].copy(),
                human_theta=human_theta[: last + 1, e].copy(),
                actions=actions[:last, e].copy(),
                rewards=rewards[:last, e].copy(),
                dmin=dmin[:last, e].copy(),
                success=bool(end.info["success"][e]),
                collision=None if collision == 0 else COLLISION_NAMES[collision],
                truncated=bool(end.truncated[e]),
                commands=executed[:last, e].copy(),
                human_group=groups[e],
                obstacle_kind=obstacle_kind[e] if obstacles else None,
                obstacle_xy=obstacle_xy[e] if obstacles else None,
                obstacle_half=obstacle_half[e] if obstacles else None,
            )
        )
    return episodes
