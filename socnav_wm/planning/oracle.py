"""``oracle-mpc``: the planner of :mod:`socnav_wm.planning.mpc` with the simulator as its model.

At every step the batched state is cloned, each episode once per candidate, and the clones are
stepped with the candidates' actions by the simulator itself, in one batched step loop. The
cost is the planner's (progress, goal, collision, discomfort), read from the clones' true state:
a contact with a wall is a collision too, since the simulator knows the walls.

SFM humans notice the robot at random, and a human that reaches its goal draws a new one at
random. The simulator's draws are a function of ``(seed, scenario, step)``, so clones stepped
under the episode's own seed would foresee the episode's future draws: a clairvoyant ceiling.
By default the clones run under a seed of the planner's own (``planning.oracle_seed``), so they
only know the humans' rules, not their future coin flips; ``planning.oracle_clairvoyant``
reuses the episode's seed and is labelled as such. ``planning.oracle_reactions`` false blinds
the clones' humans to the robot: the ceiling without knowing how people react to it.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from socnav_wm.env.core import Simulator
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_NONE, BatchState
from socnav_wm.planning.mpc import candidate_actions, command_table, prefixes, step_gain
from socnav_wm.planning.params import PlanningParams


def clone_simulator(
    sim: Simulator, repeats: int = 1, seed: int | None = None, envs: np.ndarray | None = None
) -> Simulator:
    """A new simulator whose slots are the episodes of ``sim``'s slots ``envs`` (default: all),
    each ``repeats`` times in a row (the ``n``-th episode's copies are slots
    ``n·repeats … (n+1)·repeats − 1``), in the same state.

    With ``seed`` None the clones keep ``sim``'s seed and step exactly as ``sim`` would; with
    another seed their random draws (SFM's noticing of the robot, the humans' new goals) are
    other ones.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats: expected a positive integer, got {repeats!r}")
    rows = np.arange(sim.num_envs) if envs is None else np.asarray(envs, dtype=np.int64)
    clone = Simulator(len(rows) * repeats, sim.params)
    state = sim.state
    clone.restore(
        BatchState(
            **{
                f.name: np.repeat(getattr(state, f.name)[rows], repeats, axis=0)
                for f in fields(state)
            }  # fmt: skip
        )
    )
    clone.seed = sim.seed if seed is None else int(seed) % 2**64
    clone.next_scenario = sim.next_scenario
    return clone


class OraclePlanner:
    """Receding-horizon control on clones of the true simulator (the module docstring).

    Args:
        params: the ``planning`` section (the weights, the candidates, the oracle's seed).
        env_params: the scenarios' parameters.
    """

    def __init__(self, params: PlanningParams, env_params: EnvParams) -> None:
        self.params, self.env_params = params, env_params
        self.commands = command_table(params, env_params)
        self.prefixes = prefixes(params.prefix_length, params.num_actions)
        self.num_candidates = len(self.prefixes) * len(params.continuations)

    def scores(self, sim: Simulator, envs: np.ndarray) -> np.ndarray:
        """(len(envs), candidates) returns of every candidate from the present state of the
        episodes in slots ``envs`` of ``sim``, candidate order as :class:`~.mpc.Planner`'s."""
        p, e = self.params, self.env_params
        s = self.num_candidates
        seed = None if p.oracle_clairvoyant else p.oracle_seed
        clone = clone_simulator(sim, s, seed, envs)
        state = clone.state
        if not p.oracle_reactions:
            state.human_sees_robot[:] = False
        goal = robot_frame_goal(state)
        distance = np.hypot(*(state.goal_xy - state.robot_xy).T)
        score = np.zeros(clone.num_envs)
        alive = ~state.done.copy()
        for k in range(p.horizon):
            actions = candidate_actions(self.prefixes, p.continuations, k, goal, e, self.commands)
            result = clone.step(actions)
            goal = robot_frame_goal(state)
            new_distance = np.hypot(*(state.goal_xy - state.robot_xy).T)
            centre = np.hypot(*(state.human_xy - state.robot_xy[:, None]).transpose(2, 0, 1))
            collided = result.info["collision"] != COLLISION_NONE
            reached = result.info["success"]
            gain = step_gain(p, e, distance - new_distance, centre.min(axis=1), collided, reached)
            score += np.where(alive, p.discount**k * gain, 0.0)
            alive &= ~state.done
            distance = new_distance
        return score.reshape(len(envs), s)

    def act(self, sim: Simulator) -> np.ndarray:
        """The first action (N,) of each running episode's best candidate (0 for finished
        ones, which the simulator ignores); ties go to the first in the table."""
        running = np.flatnonzero(~sim.state.done)
        if self.commands is None:
            actions = np.zeros(sim.num_envs, dtype=np.int64)
        else:
            actions = np.zeros((sim.num_envs, 2))
        if running.size:
            best = self.scores(sim, running).argmax(axis=1)
            first = self.prefixes[best // len(self.params.continuations), 0]
            actions[running] = first if self.commands is None else self.commands[first]
        return actions


def robot_frame_goal(state: BatchState) -> np.ndarray:
    """(N, 2) the goal in each robot's frame, as the observation has it."""
    c, s = np.cos(state.robot_theta), np.sin(state.robot_theta)
    dx, dy = (state.goal_xy - state.robot_xy).T
    return np.stack((c * dx + s * dy, -s * dx + c * dy), axis=-1)
