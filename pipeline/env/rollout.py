"""Run a policy in the batched simulator and record what happened, step by step.

Used by ``socnav-wm render`` (frames of a few episodes) and by anything that needs whole
trajectories (metrics, GIFs). Policies are callables from observations ``(N, obs_dim)`` to
actions ``(N,)``; the recorder keeps running envs only and never resets a slot, so slot ``i``
holds scenario ``scenario_ids[i]`` from start to end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.env.core import NUM_ACTIONS, Simulator
from pipeline.env.params import EnvParams
from pipeline.env.state import COLLISION_NAMES

Policy = Callable[[np.ndarray], np.ndarray]


def random_policy(seed: int) -> Policy:
    """Uniform over the 4 discrete actions, from its own seeded generator."""
    rng = np.random.default_rng(seed)

    def act(obs: np.ndarray) -> np.ndarray:
        return rng.integers(0, NUM_ACTIONS, size=obs.shape[0])

    return act


@dataclass(frozen=True)
class Episode:
    """One recorded episode; index ``t`` of the ``(T+1, …)`` arrays is the state after step t."""

    scenario_id: int
    robot_xy: np.ndarray  # (T+1, 2) m
    robot_theta: np.ndarray  # (T+1,) rad
    goal_xy: np.ndarray  # (2,) m
    human_xy: np.ndarray  # (T+1, H, 2) m
    human_theta: np.ndarray  # (T+1, H) rad
    actions: np.ndarray  # (T,) or (T, 2)
    rewards: np.ndarray  # (T,)
    dmin: np.ndarray  # (T,) m
    success: bool
    collision: str | None  # "human", "wall" or None
    truncated: bool

    @property
    def num_steps(self) -> int:
        return int(self.rewards.shape[0])


def run_episodes(
    params: EnvParams, policy: Policy, seed: int, scenario_ids: np.ndarray
) -> list[Episode]:
    """Run scenarios ``scenario_ids`` of ``seed`` to their end, all at once in one batch."""
    ids = np.asarray(scenario_ids, dtype=np.int64)
    sim = Simulator(len(ids), params)
    obs, info = sim.reset(seed=seed, scenario_ids=ids)
    info["human_theta"] = sim.state.human_theta()
    frames = [info]
    steps = []
    while not sim.state.done.all():
        actions = np.asarray(policy(obs))
        result = sim.step(actions)
        obs = result.obs
        result.info["human_theta"] = sim.state.human_theta()
        frames.append(result.info)
        steps.append((actions, result))
    episodes = []
    for e, scenario in enumerate(ids):
        last = int(sim.state.step_count[e])  # steps this episode took
        end = steps[last - 1][1]
        collision = int(end.info["collision"][e])
        episodes.append(
            Episode(
                scenario_id=int(scenario),
                robot_xy=np.stack([f["robot_xy"][e] for f in frames[: last + 1]]),
                robot_theta=np.array([f["robot_theta"][e] for f in frames[: last + 1]]),
                goal_xy=frames[0]["goal_xy"][e].copy(),
                human_xy=np.stack([f["human_xy"][e] for f in frames[: last + 1]]),
                human_theta=np.stack([f["human_theta"][e] for f in frames[: last + 1]]),
                actions=np.stack([a[e] for a, _ in steps[:last]]),
                rewards=np.array([r.reward[e] for _, r in steps[:last]]),
                dmin=np.array([r.info["dmin"][e] for _, r in steps[:last]]),
                success=bool(end.info["success"][e]),
                collision=None if collision == 0 else COLLISION_NAMES[collision],
                truncated=bool(end.truncated[e]),
            )
        )
    return episodes


def episode_frames(
    episode: Episode, params: EnvParams, *, label: str = "", size: int = 480
) -> list[np.ndarray]:
    """RGB frames (size, size, 3) of every state of an episode, with its trail and a caption."""
    from pipeline.env.render import Scene, render_frame

    outcome = (
        "success"
        if episode.success
        else f"{episode.collision} collision"
        if episode.collision
        else "timeout"
    )
    frames = []
    for t in range(episode.num_steps + 1):
        status = outcome if t == episode.num_steps else ""
        title = f"{label} scenario {episode.scenario_id}  step {t}  {status}".strip()
        scene = Scene(
            robot_xy=episode.robot_xy[t],
            robot_theta=float(episode.robot_theta[t]),
            robot_radius=params.robot_radius,
            goal_xy=episode.goal_xy,
            goal_radius=params.goal_radius,
            human_xy=episode.human_xy[t],
            human_theta=episode.human_theta[t],
            human_radius=params.human_radius,
            personal_space=0.5,
            room_half_size=params.wall_half_size,
            wall_thickness=params.wall_thickness,
            robot_trail=episode.robot_xy[: t + 1],
            title=title,
        )
        frames.append(render_frame(scene, size=size))
    return frames
