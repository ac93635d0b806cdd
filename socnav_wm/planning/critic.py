"""``wm-mpc-q``'s critic: a trained agent that values the planner's imagined futures and proposes
actions in them (as TD-MPC and RAY-TOLD put a learned value and policy at the end of a short
horizon).

The planner imagines the goal and the humans' positions (:mod:`socnav_wm.planning.models`); an
agent reads observations. :class:`ImaginedObservations` writes the observation the robot would
see at each imagined step, field by field as the simulator does
(:mod:`socnav_wm.env.observation`): the goal and each human in the robot's frame, the human's
heading relative to the robot's (from its imagined velocity; kept, turned with the robot, while
it stands), its radius (as last seen), the speed of the human relative to the robot, and
``−ω`` of the robot's last imagined command. :class:`AgentCritic` runs the agent's Q-network on
those observations: its greedy action (the ``policy`` continuation) and ``max_a Q`` (the value
at the horizon, weighted by ``planning.value_weight``).

Only an agent that reads the observation itself (``dueling-dqn``) can judge an imagined one: the
world-model variants would need the VAE and LSTM run along every candidate.
"""

from __future__ import annotations

import numpy as np
import torch

from socnav_wm.agents.agent_file import Agent
from socnav_wm.env.observation_layout import FEATURES_PER_HUMAN, observation_size
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.ego import Motion

CRITIC_VARIANT = "dueling-dqn"
"""The one agent variant whose input is the observation."""


class ImaginedObservations:
    """The observations of a batch of imagined futures, step by step.

    Args:
        obs: each episode's real observation now (N, obs_dim; humans only: no obstacle slots).
        repeats: futures per episode (episode-major, as the model's rollouts).
        env_params: the scenarios' parameters (``dt``).
    """

    def __init__(self, obs: np.ndarray, repeats: int, env_params: EnvParams) -> None:
        obs = np.repeat(np.asarray(obs, dtype=np.float64), repeats, axis=0)
        humans = obs[:, 2:].reshape(len(obs), -1, FEATURES_PER_HUMAN)
        self.sin_cos = humans[..., 2:4].copy()
        self.radius = humans[..., 4].copy()
        self.dt = env_params.dt

    def observe(self, points: np.ndarray, velocity: np.ndarray, motion: Motion) -> np.ndarray:
        """The observations (B, obs_dim) float32 after an imagined step: ``points`` (B, 1 + H, 2)
        the goal and humans in the robot's new frame, ``velocity`` (B, 1 + H, 2) their per-step
        displacements in that frame, ``motion`` the robot's command of the step."""
        omega = np.asarray(motion.omega, dtype=np.float64)
        turn = (omega * self.dt)[:, None]
        c, s = np.cos(turn), np.sin(turn)
        sin, cos = self.sin_cos[..., 0], self.sin_cos[..., 1]
        # The relative heading θ_h − θ_r loses the robot's turn while the human stands ...
        turned = np.stack((sin * c - cos * s, cos * c + sin * s), axis=-1)
        step = velocity[:, 1:]
        length = np.hypot(step[..., 0], step[..., 1])
        moving = length > 1e-9
        # ... and is the direction of its velocity in the robot's frame while it walks.
        heading = np.stack(
            (
                np.divide(step[..., 1], length, out=np.zeros_like(length), where=moving),
                np.divide(step[..., 0], length, out=np.ones_like(length), where=moving),
            ),
            axis=-1,
        )
        self.sin_cos = np.where(moving[..., None], heading, turned)
        robot_vy = np.zeros_like(omega) if motion.vy is None else np.asarray(motion.vy)
        relative = (
            step / self.dt
            - np.stack((np.asarray(motion.v, dtype=np.float64), robot_vy), axis=-1)[:, None]
        )
        humans = np.concatenate(
            (
                points[:, 1:],
                self.sin_cos,
                self.radius[..., None],
                np.hypot(relative[..., 0], relative[..., 1])[..., None],
                np.broadcast_to(-omega[:, None, None], (*length.shape, 1)),
            ),
            axis=-1,
        )
        return np.concatenate((points[:, 0], humans.reshape(len(points), -1)), axis=1).astype(
            np.float32
        )


class AgentCritic:
    """A trained ``dueling-dqn`` agent as a planner's critic.

    Raises:
        ValueError: the agent reads a world model's features, or observations of another size
            than the planner's scenarios (obstacle slots: the planner does not imagine them).
    """

    def __init__(self, agent: Agent, env_params: EnvParams, path: str = "the critic") -> None:
        if agent.variant_name != CRITIC_VARIANT:
            raise ValueError(
                f"{path}: wm-mpc-q's critic must read the observation ({CRITIC_VARIANT}), "
                f"not a world model's features ({agent.variant_name})"
            )
        if env_params.observed_obstacles:
            raise ValueError(
                f"{path}: wm-mpc-q imagines no obstacle slots (env.observed_obstacles "
                f"{env_params.observed_obstacles}); its critic needs observations of humans only"
            )
        expected = observation_size(env_params.num_observed_humans)
        if agent.q_network.input_dim != expected:
            raise ValueError(
                f"{path}: the critic reads {agent.q_network.input_dim} values, the planner's "
                f"observations have {expected}"
            )
        self.agent, self.env_params = agent, env_params
        self.features = agent.fresh_variant()

    def imagine(self, obs: np.ndarray, repeats: int) -> ImaginedObservations:
        """The observations of ``repeats`` futures per episode, from the episodes' now (N, D)."""
        return ImaginedObservations(obs, repeats, self.env_params)

    def evaluate(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Greedy actions (B,) int64 and values ``max_a Q`` (B,) float64 of observations (B, D)."""
        with torch.inference_mode():
            q = self.agent.q_network(self.features.reset(obs))
            value, action = q.max(dim=1)
        return action.cpu().numpy().astype(np.int64), value.cpu().numpy().astype(np.float64)
