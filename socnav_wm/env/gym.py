"""gymnasium front-ends over the batched simulator: ``SocNav-v0`` single and vector envs.

``SocNavEnv`` is a batch of one; ``SocNavVectorEnv`` is the batch, with same-step autoreset
(the final observation of a finished episode is in ``info["final_obs"]``, and the returned
observation is already the next episode's first). Both are built from the same ``Simulator``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from socnav_wm.env.core import MAX_SCENARIO_ID, NUM_ACTIONS, Simulator, StepResult
from socnav_wm.env.observation_layout import observation_size
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_NAMES

ACTION_TYPES = ("discrete", "continuous")


def _spaces(params: EnvParams, action_type: str) -> tuple[spaces.Box, spaces.Space]:
    if action_type not in ACTION_TYPES:
        raise ValueError(
            f"action_type: must be one of {', '.join(ACTION_TYPES)}, got {action_type!r}"
        )
    sim_dim = observation_size(params.num_observed_humans, params.observed_obstacles)
    # Positions are bounded by the room's diagonal; the other entries by 1 (sin, cos) or by the
    # sum of the speeds — all well inside this bound.
    bound = np.float32(params.room_size * 1.5)
    observation_space = spaces.Box(-bound, bound, shape=(sim_dim,), dtype=np.float32)
    if action_type == "discrete":
        return observation_space, spaces.Discrete(NUM_ACTIONS)
    turn = params.robot_max_speed if params.kinematics == "holonomic" else params.robot_max_rotation
    high = np.array([params.robot_max_speed, turn], dtype=np.float32)
    return observation_space, spaces.Box(-high, high, dtype=np.float32)


def _as_sim_actions(action: Any, action_type: str, num_envs: int) -> np.ndarray:
    if action_type == "discrete":
        # Integers only (Python or numpy): casting would run 1.5 or True as action 1, and a huge
        # Python int would overflow int64.
        a = np.asarray(action)
        if a.dtype.kind not in "iu" or a.size and (a.min() < 0 or a.max() >= NUM_ACTIONS):
            shown = " ".join(repr(action).split())[:60]
            raise ValueError(f"action: expected integers in 0..{NUM_ACTIONS - 1}, got {shown}")
        return a.astype(np.int64).reshape(num_envs)
    return np.asarray(action, dtype=np.float64).reshape(num_envs, 2)


class SocNavEnv(gym.Env[np.ndarray, Any]):
    """The paper's social-navigation task as a gymnasium env (a batch of one).

    Keyword options are the fields of ``EnvParams`` (``num_humans``, ``human_policy``,
    ``reward``, ``room_size``, …) plus ``action_type`` (``discrete``: the paper's 4 actions;
    ``continuous``: a (v m/s, ω rad/s) command, or with ``kinematics="holonomic"`` a (vx, vy)
    m/s velocity in the robot's frame, clipped to the robot's limits).
    ``reset(seed=s)`` starts scenario 0 of seed ``s``; later resets without a seed run scenarios
    1, 2, … of the same seed; ``reset(options={"scenario_id": i})`` runs scenario ``i``.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self, render_mode: str | None = None, action_type: str = "discrete", **env_options: Any
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: must be None or 'rgb_array', got {render_mode!r}")
        self.params = EnvParams.from_dict(env_options)
        self.action_type = action_type
        self.observation_space, self.action_space = _spaces(self.params, action_type)
        self.render_mode = render_mode
        self.sim = Simulator(1, self.params)
        self._trail: list[np.ndarray] = []

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        _check_seed(seed)
        super().reset(seed=seed)
        scenario = _reset_option(options, "scenario_id")
        if seed is not None:
            obs, info = self.sim.reset(seed=seed, scenario_ids=_one_id(scenario, 0))
        elif not self.sim.state.done.all() or self.sim.next_scenario > 0 or scenario is not None:
            # Later resets continue the same seed's scenario sequence.
            ids = _one_id(scenario, self.sim.next_scenario)
            self.sim.reset_envs(np.array([0]), ids)
            obs, info = self.sim.observation, self.sim.info()
        else:
            # First reset without a seed: draw one from gymnasium's (randomly seeded) generator.
            obs, info = self.sim.reset(seed=int(self.np_random.integers(2**31)))
        self._trail = [self.sim.state.robot_xy[0].copy()]
        return obs[0], _single_info(info)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self.sim.state.done[0]:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        result = self.sim.step(_as_sim_actions(action, self.action_type, 1))
        self._trail.append(self.sim.state.robot_xy[0].copy())
        return (
            result.obs[0],
            float(result.reward[0]),
            bool(result.terminated[0]),
            bool(result.truncated[0]),
            _single_info(result.info),
        )

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from socnav_wm.env.render import render_frame

        return render_frame(scene_of(self.sim, 0, np.array(self._trail)))


def _check_seed(seed: Any) -> None:
    """Any non-negative integer (gymnasium's rule); the simulator reduces it to 64 bits."""
    if seed is not None and (
        isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0
    ):
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")


def _reset_option(options: dict[str, Any] | None, key: str) -> Any:
    """The one option that ``reset`` takes, ``key`` (None when absent); any other is an error."""
    rest = dict(options or {})
    value = rest.pop(key, None)
    if rest:
        raise ValueError(f"reset options: unknown key(s) {', '.join(sorted(rest))}")
    return value


def _one_id(scenario: Any, default: int) -> np.ndarray:
    value = default if scenario is None else scenario
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or not 0 <= value < MAX_SCENARIO_ID
    ):
        raise ValueError(f"scenario_id: expected an integer in 0..2**62 - 1, got {value!r}")
    return np.array([int(value)])


def _single_info(info: dict[str, np.ndarray]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in info.items():
        item = value[0]
        out[key] = item.item() if np.ndim(item) == 0 else item
    if "collision" in out:
        out["collision"] = COLLISION_NAMES[int(out["collision"])]
    return out


def scene_of(sim: Simulator, env: int, trail: np.ndarray | None = None, title: str = ""):
    """The ``render.Scene`` of slot ``env`` of a simulator."""
    from socnav_wm.env.render import Scene, scene_options

    s = sim.state
    obstacles = s.obstacle_kind.shape[1] > 0
    return Scene(
        robot_xy=s.robot_xy[env].copy(),
        robot_theta=float(s.robot_theta[env]),
        goal_xy=s.goal_xy[env].copy(),
        human_xy=s.human_xy[env].copy(),
        human_theta=s.human_theta()[env],
        robot_trail=trail,
        title=title,
        obstacle_kind=s.obstacle_kind[env].copy() if obstacles else None,
        obstacle_xy=s.obstacle_xy[env].copy() if obstacles else None,
        obstacle_half=s.obstacle_half[env].copy() if obstacles else None,
        human_group=s.human_group[env].copy(),
        **scene_options(sim.params),
    )


class SocNavVectorEnv(VectorEnv):
    """``num_envs`` rooms stepped together, with same-step autoreset.

    ``info`` holds arrays with a leading ``num_envs`` axis (``robot_xy``, ``robot_theta``,
    ``goal_xy``, ``human_xy``, ``dmin``, ``success``, ``collision`` codes 0 none / 1 human /
    2 wall, ``scenario_id``, ``step``); for envs whose episode ended, ``info["final_obs"]`` and
    ``info["final_info"]`` (rows masked by ``info["_final_obs"]``) describe the last step before
    the reset, and the other entries already describe the new episode.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        render_mode: str | None = None,
        action_type: str = "discrete",
        max_episode_steps: int | None = None,
        **env_options: Any,
    ) -> None:
        self.params = EnvParams.from_dict(env_options)
        # gym.make_vec passes the spec's max_episode_steps; the env truncates itself at
        # params.max_steps, so it only has to agree.
        if max_episode_steps is not None and max_episode_steps != self.params.max_steps:
            raise ValueError(
                f"max_episode_steps: the env truncates at max_steps={self.params.max_steps}, "
                f"got {max_episode_steps!r} (pass max_steps instead)"
            )
        self.sim = Simulator(num_envs, self.params)
        self.num_envs = self.sim.num_envs
        self.action_type = action_type
        self.render_mode = render_mode
        self.single_observation_space, self.single_action_space = _spaces(self.params, action_type)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, list | tuple):
            raise ValueError("seed: the batched env takes one seed for the whole batch")
        _check_seed(seed)
        super().reset(seed=seed)
        ids = _reset_option(options, "scenario_ids")
        if seed is None and self.sim.next_scenario == 0:
            seed = int(self.np_random.integers(2**31))
        obs, info = self.sim.reset(seed=seed, scenario_ids=ids)
        return obs, info

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        result: StepResult = self.sim.step(
            _as_sim_actions(actions, self.action_type, self.num_envs)
        )
        info = result.info
        obs = result.obs
        ended = result.terminated | result.truncated
        if ended.any():
            # The step's arrays are its own copies: the final info can keep them as they are.
            info["final_info"] = dict(info)
            info["final_obs"] = obs
            info["_final_obs"] = ended
            obs = self.sim.autoreset(ended)
            info.update(self.sim.info())
        return obs, result.reward, result.terminated, result.truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        from socnav_wm.env.frames import tile_frames
        from socnav_wm.env.render import render_frame

        frames = [render_frame(scene_of(self.sim, e)) for e in range(min(self.num_envs, 16))]
        return tile_frames(frames, columns=4)
