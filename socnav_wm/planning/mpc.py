"""Receding-horizon planning over the paper's four actions (stop, forward, left, right).

At every step, for every episode at once:

1. the candidates are every ``prefix_length``-action prefix (``4**prefix_length``), each
   followed by each continuation (``goal``: turn towards the predicted goal when it is more
   than half a turn step off the heading, else advance; ``stop``; ``forward``) up to
   ``horizon`` steps;
2. the model imagines all of them in one batch (``episodes × candidates`` futures), one step
   at a time;
3. each future is scored on its predicted goal and humans, step ``k`` weighted ``γᵏ``:
   progress towards the goal (m) × ``progress_weight``, − ``discomfort_cost`` when a human is
   nearer than ``discomfort_distance`` surface to surface, − ``collision_cost`` (and the future
   ends) at a contact, + ``goal_reward`` (and the future ends) at the goal;
4. the first action of the best candidate is executed (ties: the first in the table), and the
   plan is made afresh at the next step.

With a critic (``wm-mpc-q``, :mod:`socnav_wm.planning.critic`), a trained agent reads the
observation of each imagined step: the ``policy`` continuation follows its greedy action, and a
future still running at the horizon gains ``value_weight · γ^horizon`` times its value.

Walls are not in the observation, so a model that predicts from observations does not see them.
With ``walls`` (the default) the planner itself knows the room, its tables and plants, and the
robot's pose in it, as a robot with a map and localisation does: it moves the imagined robot by
the update of each candidate action (unicycle or holonomic), and a step that brings it within
its radius of a wall or an obstacle is a collision (the simulator's test). The models still
predict only the goal and the humans.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from socnav_wm.env.core import NUM_ACTIONS
from socnav_wm.env.obstacles import nearest_points, obstacle_map
from socnav_wm.env.params import EnvParams
from socnav_wm.planning.models import PlanningModel
from socnav_wm.planning.params import PlanningParams
from socnav_wm.worldmodel.ego import Motion, advance_pose, commands_of

STOP, FORWARD, LEFT, RIGHT = range(NUM_ACTIONS)


def prefixes(length: int, num_actions: int) -> np.ndarray:
    """Every sequence of ``length`` actions out of ``num_actions``, (A**length, length) int64,
    in lexicographic order (so the first is all action 0: ``stop``)."""
    return np.array(list(itertools.product(range(num_actions), repeat=length)), dtype=np.int64)


def command_table(params: PlanningParams, env_params: EnvParams) -> np.ndarray | None:
    """The lattice's commands (A, 2), action ``a`` being row ``a`` (row 0 stops), or None for
    the paper's four discrete actions. Unicycle: every speed of ``0, v/n, …, v`` with every turn
    rate evenly in ``±ω``; holonomic: those speeds in every direction ``2πj/m`` (robot frame)."""
    if params.actions == "paper":
        return None
    e = env_params
    speeds = np.linspace(0.0, e.robot_max_speed, params.lattice_speeds + 1)
    if e.kinematics == "holonomic":
        angles = 2 * np.pi * np.arange(params.lattice_headings) / params.lattice_headings
        v, a = np.meshgrid(speeds, angles, indexing="ij")
        return np.stack((v * np.cos(a), v * np.sin(a)), axis=-1).reshape(-1, 2)
    turns = np.linspace(-e.robot_max_rotation, e.robot_max_rotation, params.lattice_headings)
    v, w = np.meshgrid(speeds, turns, indexing="ij")
    table = np.stack((v, w), axis=-1).reshape(-1, 2)
    # Stop first (ties go to the first candidate): in place of the slowest left turn when an
    # even number of turn rates leaves no zero one.
    stop = np.flatnonzero((table == 0).all(axis=1))
    rest = np.delete(table, stop[0], axis=0) if stop.size else table[1:]
    return np.vstack(([0.0, 0.0], rest))


def continuation_commands(name: str, goal: np.ndarray, env_params: EnvParams) -> np.ndarray:
    """A lattice planner's continuation ``name`` as commands (B, 2) for robot-frame goals
    (B, 2): ``stop``; ``forward`` at full speed; ``goal``, full speed towards the goal
    (holonomic) or turning towards it while advancing as far as the heading agrees (unicycle)."""
    e = env_params
    out = np.zeros((len(goal), 2))
    if name == "forward":
        out[:, 0] = e.robot_max_speed
    elif name == "goal":
        if e.kinematics == "holonomic":
            length = np.hypot(goal[:, 0], goal[:, 1])[:, None]
            np.divide(goal * e.robot_max_speed, length, out=out, where=length > 0)
        else:
            bearing = np.arctan2(goal[:, 1], goal[:, 0])
            out[:, 0] = e.robot_max_speed * np.maximum(0.0, np.cos(bearing))
            out[:, 1] = np.clip(bearing / e.dt, -e.robot_max_rotation, e.robot_max_rotation)
    return out


def towards_goal(goal: np.ndarray, env_params: EnvParams) -> np.ndarray:
    """The ``goal`` continuation's action (B,) for robot-frame goals (B, 2): rotate towards the
    goal while its bearing exceeds half a turn step, else advance."""
    bearing = np.arctan2(goal[:, 1], goal[:, 0])
    half_turn = 0.5 * env_params.robot_max_rotation * env_params.dt
    return np.where(bearing > half_turn, LEFT, np.where(bearing < -half_turn, RIGHT, FORWARD))


def candidate_actions(
    prefix_table: np.ndarray,
    continuations: tuple[str, ...],
    k: int,
    goal: np.ndarray,
    env_params: EnvParams,
    commands: np.ndarray | None = None,
    policy: np.ndarray | None = None,
) -> np.ndarray:
    """Step ``k``'s action of every future, futures in candidate order repeated per episode:
    the prefix's while ``k`` is within it, then the continuation's (``goal`` from the futures'
    robot-frame goals (B, 2); ``policy`` from ``policy``, a critic's action (B,) for every
    future). Discrete actions (B,), or with a lattice (``commands``, the
    :func:`command_table`) continuous commands (B, 2)."""
    conts = len(continuations)
    batch = len(goal)
    candidates = len(prefix_table) * conts
    rows_of = np.arange(batch) % candidates
    if k < prefix_table.shape[1]:
        index = prefix_table[rows_of // conts, k]
        return index if commands is None else commands[index]
    continuation_of = rows_of % conts
    if "policy" in continuations and (policy is None or commands is not None):
        raise ValueError(
            "planning.continuations: 'policy' follows a critic's discrete actions "
            "(wm-mpc-q, on the paper's actions)"
        )
    if commands is not None:
        out = np.empty((batch, 2))
        for c, name in enumerate(continuations):
            rows = continuation_of == c
            out[rows] = continuation_commands(name, goal[rows], env_params)
        return out
    actions = np.empty(batch, dtype=np.int64)
    for c, name in enumerate(continuations):
        rows = continuation_of == c
        if name == "goal":
            actions[rows] = towards_goal(goal[rows], env_params)
        elif name == "policy":
            actions[rows] = policy[rows]
        else:
            actions[rows] = {"stop": STOP, "forward": FORWARD}[name]
    return actions


class Imagined(Protocol):
    """The observations of a batch of imagined futures (a critic's, :meth:`Critic.imagine`)."""

    def observe(self, points: np.ndarray, velocity: np.ndarray, motion: Motion) -> np.ndarray:
        """The observations (B, obs_dim) after a step: the predicted positions and per-step
        velocities (B, 1 + H, 2) in the robot's new frame and the robot's command."""
        ...


class Critic(Protocol):
    """What values imagined futures (:class:`socnav_wm.planning.critic.AgentCritic`, imported
    by ``wm-mpc-q``'s builder only: torch and the agent file stay out of the other planners)."""

    def imagine(self, obs: np.ndarray, repeats: int) -> Imagined:
        """The futures' observations, ``repeats`` per episode from its observation (N, D)."""
        ...

    def evaluate(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Greedy actions (B,) and values (B,) of observations (B, D)."""
        ...


def step_gain(
    params: PlanningParams,
    env_params: EnvParams,
    progress: np.ndarray,
    centre: np.ndarray,
    collided: np.ndarray,
    reached: np.ndarray,
) -> np.ndarray:
    """One predicted step's term of the cost (the module docstring's step 3), undiscounted:
    ``progress`` (m towards the goal), ``centre`` (distance to the nearest human's centre, m),
    ``collided`` and ``reached`` (bool), all (B,)."""
    p, e = params, env_params
    uncomfortable = centre - e.robot_radius - e.human_radius < e.discomfort_distance
    return (
        p.progress_weight * progress
        - p.discomfort_cost * uncomfortable
        - p.collision_cost * collided
        + p.goal_reward * reached
    )


class Planner:
    """The planner of the module docstring, with ``model`` as its predictor.

    Args:
        model: a :class:`~socnav_wm.planning.models.PlanningModel`, following the episodes.
        params: the ``planning`` section.
        env_params: the scenarios' parameters (radii, goal and discomfort distances, turn step).
        critic: a :class:`Critic` (``wm-mpc-q``'s trained agent): the
            ``policy`` continuation and the value at the horizon. Without one, ``policy`` is
            refused.
    """

    def __init__(
        self,
        model: PlanningModel,
        params: PlanningParams,
        env_params: EnvParams,
        critic: Critic | None = None,
    ):
        if critic is None and "policy" in params.continuations:
            raise ValueError(
                "planning.continuations: 'policy' needs a critic (an agent); only wm-mpc-q has one"
            )
        self.model, self.params, self.env_params = model, params, env_params
        self.critic = critic
        self.commands = command_table(params, env_params)
        self.prefixes = prefixes(params.prefix_length, params.num_actions)
        self.num_candidates = len(self.prefixes) * len(params.continuations)

    def scores(
        self,
        goal_now: np.ndarray,
        pose: np.ndarray | None = None,
        obstacles: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        rows: np.ndarray | None = None,
        obs: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N, candidates) predicted returns from the model's present, where the goal is at
        ``goal_now`` (N, 2) in the robot frame; candidate ``p · len(continuations) + c`` is
        prefix ``p`` followed by continuation ``c``. With ``pose`` (N, 3: the robot's x, y, θ
        in the room), touching a wall is a collision, and so is touching one of ``obstacles``
        (each episode's tables and plants: kinds (N, O), centres (N, O, 2), half sizes).
        ``rows``: the model's episodes these are (indices; None: all of them, in order).
        ``obs`` (N, obs_dim): their observations now, which a critic needs."""
        p, e = self.params, self.env_params
        imagined = policy = None
        if self.critic is not None:
            if obs is None:
                raise ValueError("a planner with a critic needs the observations")
            imagined = self.critic.imagine(obs, self.num_candidates)
        num_episodes = len(goal_now)
        s = self.num_candidates
        rollout = self.model.rollout(s, pose, rows)
        batch = num_episodes * s
        score = np.zeros(batch)
        alive = np.ones(batch, dtype=bool)
        goal = np.repeat(np.asarray(goal_now, dtype=np.float64), s, axis=0)
        goal_distance = np.hypot(goal[:, 0], goal[:, 1])
        contact = e.robot_radius + e.human_radius + p.safety_margin
        wall_limit = e.wall_half_size - e.robot_radius - p.safety_margin
        robot = None if pose is None else np.repeat(np.asarray(pose, dtype=np.float64), s, axis=0)
        if robot is not None and obstacles is not None:
            obstacles = tuple(np.repeat(a, s, axis=0) for a in obstacles)
            obstacle_limit = e.robot_radius + p.safety_margin
        for k in range(p.horizon):
            actions = candidate_actions(
                self.prefixes, p.continuations, k, goal, e, self.commands, policy
            )
            predicted = rollout.step(actions)
            if imagined is not None:
                seen = imagined.observe(predicted, rollout.velocities(), commands_of(actions, e))
                policy, value = self.critic.evaluate(seen)
            goal = predicted[:, 0]
            new_goal_distance = np.hypot(goal[:, 0], goal[:, 1])
            centre = np.hypot(predicted[:, 1:, 0], predicted[:, 1:, 1]).min(axis=1)
            collided = centre < contact
            if robot is not None:
                robot = advance_pose(robot, commands_of(actions, e), e.dt)
                collided |= np.abs(robot[:, :2]).max(axis=1) >= wall_limit
                if obstacles is not None:
                    _, gap = nearest_points(robot[:, :2], *obstacles)
                    collided |= gap.min(axis=1) <= obstacle_limit
            reached = ~collided & (new_goal_distance < e.success_distance)
            score += np.where(
                alive,
                p.discount**k
                * step_gain(p, e, goal_distance - new_goal_distance, centre, collided, reached),
                0.0,
            )
            alive &= ~(collided | reached)
            goal_distance = new_goal_distance
        if imagined is not None:  # the critic's value of the futures still running
            score += np.where(alive, p.value_weight * p.discount**p.horizon * value, 0.0)
        return score.reshape(num_episodes, s)

    def act(
        self,
        obs: np.ndarray,
        pose: np.ndarray | None = None,
        obstacles: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        running: np.ndarray | None = None,
    ) -> np.ndarray:
        """The first action (N,) of each episode's best candidate, from the model's present
        (whose observation is ``obs``; ``pose`` (N, 3): the robot's in the room, for the
        walls; ``obstacles``: the room's tables and plants). With ``running`` (N,) bool, only
        those episodes are planned (an ended one gets action 0, which nothing executes): the
        same actions for them, at the cost of the episodes still running."""
        goal = np.asarray(obs, dtype=np.float64)[:, :2]
        first = np.zeros(len(goal), dtype=np.int64)
        rows = np.arange(len(goal)) if running is None else np.flatnonzero(running)
        if len(rows):
            scores = self.scores(
                goal[rows],
                None if pose is None else pose[rows],
                None if obstacles is None else tuple(a[rows] for a in obstacles),
                rows,
                None if self.critic is None else np.asarray(obs)[rows],
            )
            best = scores.argmax(axis=1)  # the first of equal scores
            first[rows] = self.prefixes[best // len(self.params.continuations), 0]
        return first if self.commands is None else self.commands[first]

    @property
    def reads_simulator(self) -> bool:
        """Whether :meth:`policy` takes the simulator (for the robot's pose: ``walls``) rather
        than the observations."""
        return self.params.walls

    def policy(self) -> Callable[[Any], np.ndarray]:
        """A policy for episodes that start together (what
        :func:`socnav_wm.env.rollout.run_episodes` calls): ``obs (N, obs_dim) → actions (N,)``,
        or with ``walls`` ``simulator → actions``, which reads the observations and the robot's
        pose (and nothing else of the simulator's state). Its first call starts the model on
        the episodes, every later call is their next step."""
        last: list[np.ndarray] = []

        def act(
            obs: np.ndarray,
            pose: np.ndarray | None = None,
            obstacles: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
            running: np.ndarray | None = None,
        ) -> np.ndarray:
            if last:
                self.model.observe(obs, last[0])
            else:
                self.model.reset(obs)
            actions = self.act(obs, pose, obstacles, running)
            last[:] = [actions]
            return actions

        if not self.params.walls:
            return act

        def localised(sim: Any) -> np.ndarray:
            # The ended episodes wait for the batch's last one: only the running are planned.
            return act(
                sim.observation, sim.state.robot_pose(), obstacle_map(sim.state), ~sim.state.done
            )

        return localised
