"""Planning models: what a planner predicts the goal and the humans with.

A model follows the real episodes (:meth:`reset` on their first observation, :meth:`observe`
after each real step) and, when asked, starts a batch of imagined futures from the present
(:meth:`rollout`), ``repeats`` per episode, which the planner steps with candidate actions.
Positions are robot-frame arrays ``(B, 1 + H, 2)``: the goal, then each human (as
:func:`socnav_wm.worldmodel.ego.positions`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from socnav_wm.env.observation_layout import observation_size
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.ego import advance, commands_of, human_velocities, positions


class Rollout(Protocol):
    """A batch of imagined futures."""

    def step(self, actions: np.ndarray) -> np.ndarray:
        """Advance every future by one action (B,); the predicted positions (B, 1 + H, 2)."""
        ...

    def velocities(self) -> np.ndarray:
        """The futures' per-step velocities (B, 1 + H, 2) in the robot's frame after the last
        step (what the next step will move them by; a critic reads the humans' headings)."""
        ...


class PlanningModel(Protocol):
    """Follows the real episodes and imagines futures from the present."""

    def reset(self, obs: np.ndarray) -> None:
        """The episodes' first observations (N, obs_dim)."""
        ...

    def observe(self, obs: np.ndarray, actions: np.ndarray) -> None:
        """The real step: ``actions`` (N,) were executed, then ``obs`` (N, obs_dim) was seen."""
        ...

    def rollout(
        self, repeats: int, pose: np.ndarray | None = None, rows: np.ndarray | None = None
    ) -> Rollout:
        """``repeats`` futures per episode, episode-major (episode ``n``'s are rows
        ``n·repeats … (n+1)·repeats − 1``), of the episodes ``rows`` (indices, in that order;
        None: every episode). ``pose`` (len(rows), 3): their robot's room pose (x, y, θ) when
        the planner knows it (``planning.walls``), for a model that uses the room; a model that
        does not ignores it. An episode's futures do not depend on which others are imagined
        with it."""
        ...


class _ConstantVelocityRollout:
    def __init__(self, points: np.ndarray, velocity: np.ndarray, params: EnvParams) -> None:
        self.points, self.velocity, self.params = points, velocity, params

    def step(self, actions: np.ndarray) -> np.ndarray:
        motion = commands_of(actions, self.params)
        self.points, self.velocity = advance(self.points, self.velocity, motion, self.params.dt)
        return self.points

    def velocities(self) -> np.ndarray:
        return self.velocity


class ConstantVelocityModel:
    """Each human keeps the world velocity of its last step, the goal stays where it is, and
    the robot's own motion is applied exactly from the action (no learning).

    A human's velocity is its displacement between the last two observations once the robot's
    motion is undone (:func:`socnav_wm.worldmodel.ego.human_velocities`); at an episode's first
    step, with one observation, it is zero.
    """

    def __init__(self, params: EnvParams) -> None:
        if params.num_observed_humans != params.num_humans:
            raise ValueError(
                f"env.observed_humans: constant velocity follows each human from one observation "
                f"to the next, so it needs every human in spawn order (observed_humans "
                f"{params.num_observed_humans} != num_humans {params.num_humans})"
            )
        self.params = params
        self._width = observation_size(params.num_humans)
        self._points = np.zeros((0, 1 + params.num_humans, 2))
        self._velocity = np.zeros_like(self._points)
        self._obs = np.zeros((0, 0))

    def reset(self, obs: np.ndarray) -> None:
        self._obs = np.asarray(obs, dtype=np.float64)[:, : self._width]
        self._points = positions(self._obs)
        self._velocity = np.zeros_like(self._points)

    def observe(self, obs: np.ndarray, actions: np.ndarray) -> None:
        obs = np.asarray(obs, dtype=np.float64)[:, : self._width]  # the humans, not obstacles
        self._velocity = human_velocities(self._obs, obs, actions, self.params)
        self._obs, self._points = obs, positions(obs)

    def rollout(
        self, repeats: int, pose: np.ndarray | None = None, rows: np.ndarray | None = None
    ) -> Rollout:
        chosen = slice(None) if rows is None else rows
        return _ConstantVelocityRollout(
            np.repeat(self._points[chosen], repeats, axis=0),
            np.repeat(self._velocity[chosen], repeats, axis=0),
            self.params,
        )
