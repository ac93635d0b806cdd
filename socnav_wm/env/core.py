"""The batched simulator: the one implementation of the dynamics behind every env in socnav-wm.

``Simulator`` steps ``num_envs`` rooms at once. Each step, in the paper environment's order:
the robot turns then advances; the humans (SFM and/or ORCA) compute their velocities from the
new snapshot and move; then goal, collision and timeout are checked (in that order), ``dmin``
and the reward are computed, and the robot-frame observation is built.

The hot loops are numba kernels over the whole batch (``humans``, ``orca``, ``reward``,
``observation``): with three humans per room, per-env arrays are tiny, and a compiled loop over
environments is several times faster than numpy broadcasting, which would spend its time in
per-call overhead — and it keeps a batch of one fast too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from socnav_wm.env.crossing import spawn_crossing
from socnav_wm.env.geometry import norm
from socnav_wm.env.humans import HumanDynamics
from socnav_wm.env.observation import observe
from socnav_wm.env.observation_layout import observation_size
from socnav_wm.env.obstacles import disc_clearance
from socnav_wm.env.params import EnvParams
from socnav_wm.env.reward import (
    REWARD_CODES,
    compute_dmin,
    compute_reward,
    point_to_segment_distance,
)
from socnav_wm.env.scenario import FAMILY_CODES, POLICY_CODES, SEES_CODES, spawn
from socnav_wm.env.state import (
    COLLISION_HUMAN,
    COLLISION_NONE,
    COLLISION_OBSTACLE,
    COLLISION_WALL,
    BatchState,
)
from socnav_wm.resources import check_fits

ACTION_NAMES = ("stop", "forward", "rotate-left", "rotate-right")
NUM_ACTIONS = len(ACTION_NAMES)
# Scenario ids are int64 in the kernels, and later resets count up from the largest one used.
MAX_SCENARIO_ID = 2**62


def discrete_commands(params: EnvParams) -> np.ndarray:
    """(4, 2) table of the paper's actions, stop, forward, left, right: (v m/s, ω rad/s) for the
    unicycle; for the holonomic robot (vx, vy) m/s in its frame, translations at full speed."""
    v, w = params.robot_max_speed, params.robot_max_rotation
    if params.kinematics == "holonomic":
        return np.array([[0.0, 0.0], [v, 0.0], [0.0, v], [0.0, -v]])
    return np.array([[0.0, 0.0], [v, 0.0], [0.0, w], [0.0, -w]])


@dataclass(frozen=True)
class StepResult:
    """What one batched step returns; arrays have a leading ``num_envs`` axis."""

    obs: np.ndarray  # (N, obs_dim) float32
    reward: np.ndarray  # (N,) float64
    terminated: np.ndarray  # (N,) bool: goal reached or collision
    truncated: np.ndarray  # (N,) bool: step limit reached without termination
    info: dict[str, np.ndarray]


@numba.njit(cache=True, error_model="numpy")
def _advance_holonomic(
    active: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    robot_v: np.ndarray,
    robot_vy: np.ndarray,
    dt: float,
) -> None:
    """Holonomic update: move by the robot-frame velocity (vx, vy)·dt; the heading stays."""
    for e in range(active.shape[0]):
        if not active[e]:
            continue
        c = math.cos(robot_theta[e])
        s = math.sin(robot_theta[e])
        robot_xy[e, 0] += (vx[e] * c - vy[e] * s) * dt
        robot_xy[e, 1] += (vx[e] * s + vy[e] * c) * dt
        robot_v[e] = vx[e]
        robot_vy[e] = vy[e]


@numba.njit(cache=True, error_model="numpy")
def _advance_robot(
    active: np.ndarray,
    v: np.ndarray,
    omega: np.ndarray,
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    robot_v: np.ndarray,
    robot_omega: np.ndarray,
    dt: float,
) -> None:
    """Unicycle update of the paper's robot: turn first (θ wrapped to (−π, π]), then advance."""
    for e in range(active.shape[0]):
        if not active[e]:
            continue
        theta = robot_theta[e] + omega[e] * dt
        # Wrap to (−π, π]; one turn is at most |ω|·dt, so one correction is enough for any
        # command the robot can execute.
        while theta > math.pi:
            theta -= 2.0 * math.pi
        while theta <= -math.pi:
            theta += 2.0 * math.pi
        robot_theta[e] = theta
        robot_xy[e, 0] += v[e] * dt * math.cos(theta)
        robot_xy[e, 1] += v[e] * dt * math.sin(theta)
        robot_v[e] = v[e]
        robot_omega[e] = omega[e]


@numba.njit(cache=True, error_model="numpy")
def _outcomes(
    active: np.ndarray,
    robot_xy: np.ndarray,
    goal_xy: np.ndarray,
    human_xy: np.ndarray,
    robot_before: np.ndarray,
    human_before: np.ndarray,
    swept: bool,
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
    robot_radius: float,
    step_count: np.ndarray,
    success_distance: float,
    contact_distance: float,
    wall_limit: float,
    max_steps: int,
    success: np.ndarray,
    collision: np.ndarray,
    truncated: np.ndarray,
) -> None:
    """Goal, then collision (human, obstacle, wall), then timeout — the paper's order. With
    ``swept``, a human also collides when the two discs touched during the step, each moving
    in a straight line from its position ``*_before`` the step (CrowdNav's test)."""
    for e in range(active.shape[0]):
        success[e] = False
        collision[e] = COLLISION_NONE
        truncated[e] = False
        if not active[e]:
            continue
        step_count[e] += 1
        rx = robot_xy[e, 0]
        ry = robot_xy[e, 1]
        if norm(goal_xy[e, 0] - rx, goal_xy[e, 1] - ry) < success_distance:
            success[e] = True
            continue
        for h in range(human_xy.shape[1]):
            if norm(human_xy[e, h, 0] - rx, human_xy[e, h, 1] - ry) <= contact_distance:
                collision[e] = COLLISION_HUMAN
                break
            if swept:
                # The relative motion over the step, from the relative position before it.
                bx = human_before[e, h, 0] - robot_before[e, 0]
                by = human_before[e, h, 1] - robot_before[e, 1]
                ax = human_xy[e, h, 0] - rx
                ay = human_xy[e, h, 1] - ry
                if point_to_segment_distance(bx, by, ax, ay) <= contact_distance:
                    collision[e] = COLLISION_HUMAN
                    break
        clearance = disc_clearance(
            e, rx, ry, robot_radius, obstacle_kind, obstacle_xy, obstacle_half
        )
        if collision[e] == COLLISION_NONE and clearance <= 0.0:
            collision[e] = COLLISION_OBSTACLE
        if collision[e] == COLLISION_NONE and (abs(rx) >= wall_limit or abs(ry) >= wall_limit):
            collision[e] = COLLISION_WALL
        if collision[e] == COLLISION_NONE and step_count[e] >= max_steps:
            truncated[e] = True


class Simulator:
    """``num_envs`` social-navigation rooms stepped together.

    Episodes do not reset themselves: a slot whose episode ended is ``done`` and ignores actions
    until ``reset_envs`` gives it a new scenario (the gymnasium wrappers do that automatically).
    Scenario ``i`` of a seed is a pure function of ``(seed, i)``: ``reset`` puts scenarios
    ``0..N−1`` in the slots (or the ``scenario_ids`` given), and ``reset_envs`` hands out the next
    unused ids in slot order.
    """

    def __init__(self, num_envs: int, params: EnvParams | None = None) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer):
            raise ValueError(f"num_envs: expected a positive integer, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs: must be >= 1, got {num_envs}")
        self.params = params if params is not None else EnvParams()
        self.num_envs = int(num_envs)
        self.obs_dim = observation_size(
            self.params.num_observed_humans, self.params.observed_obstacles
        )
        # The state, the observations and a step's temporaries: refuse in one line what the
        # machine cannot hold rather than allocate until MemoryError.
        needed = self.bytes_needed(self.num_envs, self.params)
        check_fits("num_envs", needed, f"{self.num_envs:,} environments")
        self.state = BatchState.zeros(
            self.num_envs,
            self.params.num_humans,
            self.params.max_obstacles,
            self.params.max_groups,
        )
        self.state.done[:] = True
        self.seed = 0
        self.next_scenario = 0
        self._humans = HumanDynamics(self.params, self.num_envs)
        self._commands = discrete_commands(self.params)
        self._obs = np.zeros((self.num_envs, self.obs_dim), dtype=np.float32)
        self._all = np.arange(self.num_envs)
        self._dmin = np.zeros(self.num_envs)
        self._reward = np.zeros(self.num_envs)
        self._success = np.zeros(self.num_envs, dtype=bool)
        self._collision = np.zeros(self.num_envs, dtype=np.int8)
        self._truncated = np.zeros(self.num_envs, dtype=bool)
        self._policy_mode = (
            -1 if self.params.human_policy == "mixed" else POLICY_CODES[self.params.human_policy]
        )
        self._family = FAMILY_CODES[self.params.scenario]
        self._sees_mode = SEES_CODES[self.params.humans_see_robot]
        speed_range = self.params.human_speed_range
        self._speed_range = np.array(speed_range if speed_range is not None else (0.0, 0.0))
        self._obstacle_counts = np.array((*self.params.tables, *self.params.plants), np.int64)
        self._table_half = np.array(self.params.table_size) / 2.0
        self._group_counts = np.array((*self.params.groups, *self.params.standing_groups), np.int64)
        self._group_sizes = np.array(self.params.group_size, np.int64)
        self._robot_before = np.zeros((self.num_envs, 2))
        self._human_before = np.zeros((self.num_envs, self.params.num_humans, 2))

    # ------------------------------------------------------------------ reset
    def reset(
        self, seed: int | None = None, scenario_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Start scenarios ``scenario_ids`` (default ``0..N−1``) of ``seed`` in every slot."""
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
                raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
            # The counter-based generator keys on the seed's 64 bits (np.uint64(seed)): larger
            # seeds are reduced modulo 2**64, so seeds below 2**64 keep their scenarios.
            self.seed = int(seed) % 2**64
        if scenario_ids is None:
            scenario_ids = np.arange(self.num_envs)
        self.next_scenario = 0
        self._reset_slots(self._all, scenario_ids)
        self.next_scenario = max(self.next_scenario, int(np.max(scenario_ids)) + 1)
        return self._obs.copy(), self.info()

    def reset_envs(self, envs: np.ndarray, scenario_ids: np.ndarray | None = None) -> None:
        """Give the slots ``envs`` (indices or a boolean mask) fresh scenarios."""
        envs = np.asarray(envs)
        if envs.dtype == bool:
            envs = np.flatnonzero(envs)
        if envs.size == 0:
            return
        if scenario_ids is None:
            scenario_ids = self.next_scenario + np.arange(envs.size)
        self._reset_slots(envs, scenario_ids)
        self.next_scenario = max(self.next_scenario, int(np.max(scenario_ids)) + 1)

    def autoreset(self, ended: np.ndarray, limit: int | None = None) -> np.ndarray:
        """Same-step autoreset, the one for every batched loop (the vector env, collection,
        training, the benchmarks): give the slots whose episode ended (``ended``: a mask or
        indices) the seed's next scenarios, only the first ``limit`` of them when a limit is
        given (collection hands out no more scenarios than it needs), and return the
        observations to act on next: the new episodes' first ones where a slot restarted."""
        envs = np.asarray(ended)
        if envs.dtype == bool:
            envs = np.flatnonzero(envs)
        if limit is not None:
            envs = envs[: max(limit, 0)]
        self.reset_envs(envs)
        return self.observation

    def _reset_slots(self, envs: np.ndarray, scenario_ids: np.ndarray) -> None:
        envs = np.ascontiguousarray(envs, dtype=np.int64)
        ids = np.asarray(scenario_ids)
        if (
            ids.dtype.kind not in "iu"
            or ids.size
            and not (ids.min() >= 0 and ids.max() < MAX_SCENARIO_ID)
        ):
            raise ValueError("scenario_ids: expected integers in 0..2**62 - 1")
        ids = np.ascontiguousarray(ids, dtype=np.int64)
        if ids.shape != envs.shape:
            raise ValueError(
                f"scenario_ids: expected {envs.size} ids (one per env), got shape {ids.shape}"
            )
        p = self.params
        s = self.state
        if self._family == 0:
            failures = spawn(
                envs, self._kernel_seed, ids, self._policy_mode, p.spawn_half_size,
                p.wall_half_size, p.robot_radius, p.human_radius, p.human_max_speed,
                p.goal_radius, p.human_goal_radius, p.min_goal_distance, self._speed_range,
                self._sees_mode, p.ignore_robot_prob, self._obstacle_counts, self._table_half,
                p.plant_radius, self._group_counts, self._group_sizes, s.robot_xy,
                s.robot_theta, s.goal_xy, s.human_xy, s.human_heading, s.human_speed,
                s.human_goal, s.human_goal_index, s.human_policy, s.human_max_speed,
                s.human_sees_robot, s.obstacle_kind, s.obstacle_xy, s.obstacle_half,
                s.human_group, s.group_leader, s.group_standing,
            )  # fmt: skip
        else:
            failures = spawn_crossing(
                envs, self._kernel_seed, ids, self._policy_mode, self._family,
                p.crossing_radius, p.crossing_noise, p.robot_radius, p.human_radius,
                p.human_max_speed, p.discomfort_distance, self._speed_range, self._sees_mode,
                p.ignore_robot_prob, s.robot_xy, s.robot_theta, s.goal_xy, s.human_xy,
                s.human_heading, s.human_speed, s.human_goal, s.human_goal_index,
                s.human_policy, s.human_max_speed, s.human_sees_robot,
            )  # fmt: skip
        if failures:
            raise RuntimeError(
                f"could not place {p.num_humans} humans and the goals in a {p.room_size} m room "
                f"without overlaps ({failures} discs ran out of spawn attempts); "
                "reduce env.num_humans or enlarge env.room_size"
            )
        s.scenario_id[envs] = ids
        s.start_xy[envs] = s.robot_xy[envs]
        s.robot_v[envs] = 0.0
        s.robot_omega[envs] = 0.0
        s.robot_vy[envs] = 0.0
        s.step_count[envs] = 0
        s.alive_sum[envs] = 0.0
        s.discomfort_sum[envs] = 0.0
        s.done[envs] = False
        self._humans.reset_obstacles(s, envs)
        self._observe(envs)

    def restore(self, state: BatchState) -> None:
        """Take ``state`` as the slots' state (e.g. copies of another simulator's episodes, as
        the oracle's clones are), with what the dynamics derive from it (the obstacles'
        polygons)."""
        self.state = state
        self._humans.reset_obstacles(state)

    @staticmethod
    def bytes_needed(num_envs: int, params: EnvParams) -> int:
        """What ``num_envs`` environments of ``params`` allocate: the state, the observations
        and a step's temporaries (about four copies of the state; measured: 1.0 KiB an
        environment of three humans, against 1.2 estimated)."""
        zeros = BatchState.zeros(1, params.num_humans, params.max_obstacles, params.max_groups)
        one_env = sum(a.nbytes for a in vars(zeros).values())
        return 4 * one_env * int(num_envs)

    # ------------------------------------------------------------------ step
    def _observe(self, envs: np.ndarray) -> None:
        """Write the observations of environments ``envs`` into the observation buffer."""
        s = self.state
        p = self.params
        observe(
            s.robot_xy,
            s.robot_theta,
            s.robot_v,
            s.robot_omega,
            s.robot_vy,
            s.goal_xy,
            s.human_xy,
            s.human_heading,
            s.human_speed,
            p.human_radius,
            p.num_observed_humans,
            s.obstacle_kind,
            s.obstacle_xy,
            s.obstacle_half,
            p.observed_obstacles,
            envs,
            self._obs,
        )

    def commands(self, actions: Any) -> tuple[np.ndarray, np.ndarray]:
        """(v, ω) arrays (holonomic: (vx, vy)) from discrete actions (N,) or continuous commands
        (N, 2), clipped."""
        a = np.asarray(actions)
        n = self.num_envs
        if a.ndim == 1 and a.shape[0] == n and np.issubdtype(a.dtype, np.integer):
            if a.size and (a.min() < 0 or a.max() >= NUM_ACTIONS):
                bad = a[(a < 0) | (a >= NUM_ACTIONS)][0]
                raise ValueError(f"action: must be in 0..{NUM_ACTIONS - 1}, got {bad}")
            table = self._commands[a]
            return table[:, 0], table[:, 1]
        if a.shape == (n, 2) and np.issubdtype(a.dtype, np.floating):
            if not np.all(np.isfinite(a)):
                raise ValueError("action: continuous commands must be finite")
            p = self.params
            if p.kinematics == "holonomic":  # (vx, vy): the speed clipped, not each component
                a = a.astype(np.float64)
                speed = np.hypot(a[:, 0], a[:, 1])
                scale = p.robot_max_speed / np.maximum(speed, p.robot_max_speed)
                return a[:, 0] * scale, a[:, 1] * scale
            v = np.clip(a[:, 0], -p.robot_max_speed, p.robot_max_speed)
            w = np.clip(a[:, 1], -p.robot_max_rotation, p.robot_max_rotation)
            return v.astype(np.float64), w.astype(np.float64)
        raise ValueError(
            f"action: expected {n} integer actions in 0..{NUM_ACTIONS - 1} or an ({n}, 2) float "
            f"array of (v m/s, omega rad/s) (holonomic: (vx, vy) m/s), got {a.dtype} array of "
            f"shape {a.shape}"
        )

    def step(self, actions: Any) -> StepResult:
        """Advance every running episode by one step; finished slots are left untouched."""
        v, omega = self.commands(actions)
        p = self.params
        s = self.state
        active = ~s.done
        if p.swept_collision:
            np.copyto(self._robot_before, s.robot_xy)
            np.copyto(self._human_before, s.human_xy)
        if p.kinematics == "holonomic":
            _advance_holonomic(
                active, v, omega, s.robot_xy, s.robot_theta, s.robot_v, s.robot_vy, p.dt
            )
        else:
            _advance_robot(
                active, v, omega, s.robot_xy, s.robot_theta, s.robot_v, s.robot_omega, p.dt
            )
        velocity = self._humans.velocities(self._kernel_seed, s)
        self._humans.move(self._kernel_seed, s, velocity, active)
        _outcomes(
            active,
            s.robot_xy,
            s.goal_xy,
            s.human_xy,
            self._robot_before,
            self._human_before,
            p.swept_collision,
            s.obstacle_kind,
            s.obstacle_xy,
            s.obstacle_half,
            p.robot_radius,
            s.step_count,
            p.success_distance,
            p.robot_radius + p.human_radius,
            p.wall_half_size - p.robot_radius,
            p.max_steps,
            self._success,
            self._collision,
            self._truncated,
        )
        compute_dmin(
            s.robot_xy,
            s.robot_theta,
            s.robot_v,
            s.robot_omega,
            s.robot_vy,
            s.human_xy,
            s.human_heading,
            s.human_speed,
            p.robot_radius,
            p.human_radius,
            p.dt,
            self._dmin,
        )
        terminated = self._success | (self._collision != COLLISION_NONE)
        failure = (self._collision != COLLISION_NONE) | self._truncated
        compute_reward(
            REWARD_CODES[p.reward],
            active,
            self._dmin,
            self._success,
            failure,
            s.alive_sum,
            s.discomfort_sum,
            p.reach_reward,
            p.failure_reward,
            p.alive_penalty,
            p.discomfort_distance,
            p.discomfort_factor,
            self._reward,
        )
        envs = np.flatnonzero(active)
        self._observe(envs)
        truncated = self._truncated.copy()
        s.done |= terminated | truncated
        info = self.info()
        info["dmin"] = np.where(active, self._dmin, np.nan)
        info["success"] = self._success.copy()
        info["collision"] = self._collision.copy()
        info["active"] = active
        return StepResult(
            obs=self._obs.copy(),
            reward=self._reward.copy(),
            terminated=terminated,
            truncated=truncated,
            info=info,
        )

    def info(self) -> dict[str, np.ndarray]:
        """Copies of what metrics and rendering need: poses, humans, goal, scenario, step."""
        s = self.state
        return {
            "robot_xy": s.robot_xy.copy(),
            "robot_theta": s.robot_theta.copy(),
            "goal_xy": s.goal_xy.copy(),
            "human_xy": s.human_xy.copy(),
            "scenario_id": s.scenario_id.copy(),
            "step": s.step_count.copy(),
        }

    @property
    def _kernel_seed(self) -> int:
        """The seed as the kernels' int64: same 64 bits, so np.uint64(seed) there is unchanged."""
        return self.seed - 2**64 if self.seed >= 2**63 else self.seed

    @property
    def observation(self) -> np.ndarray:
        """(N, obs_dim) float32 copy of the current observations."""
        return self._obs.copy()
