"""Human motion: the Social Force Model of the paper's environment, ORCA, and the position update.

Both policies are computed for the whole batch at once; each human then follows the one it drew
at spawn (``state.human_policy``). All humans move simultaneously from the same snapshot (the
paper's environment updated them one after the other, so later humans saw earlier ones' new
positions; a batched simulator has no such order, and the difference is a fraction of a step).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env import orca
from socnav_wm.env.geometry import norm
from socnav_wm.env.params import EnvParams
from socnav_wm.env.scenario import (
    POLICY_ORCA,
    POLICY_SFM,
    STREAM_AVOID_ROBOT,
    redraw_human_goal,
    uniform,
)
from socnav_wm.env.state import BatchState

# exp(-x) below exp(-40) ≈ 4e-18 is lost next to the desired force (≈ 0.08): skip the call.
_EXP_CUTOFF = 40.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def _wall_push(gap: float, r0: float) -> float:
    """exp(−gap/r0), the paper's obstacle repulsion, skipped where it underflows."""
    x = gap / r0
    return math.exp(-x) if x < _EXP_CUTOFF else 0.0


@numba.njit(cache=True, error_model="numpy")
def sfm_velocities(
    seed: int,
    scenario_id: np.ndarray,
    step_count: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_goal: np.ndarray,
    human_policy: np.ndarray,
    robot_xy: np.ndarray,
    wall_half: float,
    human_radius: float,
    robot_radius: float,
    max_speed: float,
    avoid_robot_prob: float,
    r0: float,
    gamma: float,
    n: float,
    n_prime: float,
    lam: float,
    weight: float,
    dt: float,
    out: np.ndarray,
) -> None:
    """Social-force velocities (N, H, 2) in m/s, written into ``out`` for SFM humans only.

    The force is the paper environment's (paper_spec §1): a desired term ``max_speed·e_goal``,
    exponential repulsion ``exp(−d/r0)·e_o`` from each wall (and from the robot, with
    probability ``avoid_robot_prob`` per human per step), and the Moussaïd-style interaction
    force of every other human; each term weighted by ``weight``. Velocity = force/m·dt, m = 1,
    capped at ``max_speed``.
    """
    num_envs, num_humans = human_speed.shape
    for e in range(num_envs):
        for i in range(num_humans):
            if human_policy[e, i] != POLICY_SFM:
                continue
            px = human_xy[e, i, 0]
            py = human_xy[e, i, 1]
            # Desired force towards the goal at full speed.
            gx = human_goal[e, i, 0] - px
            gy = human_goal[e, i, 1] - py
            gnorm = norm(gx, gy)
            fx = 0.0
            fy = 0.0
            if gnorm > 0.0:
                fx = weight * max_speed * gx / gnorm
                fy = weight * max_speed * gy / gnorm
            # Walls: the nearest point of each wall is on its inner face.
            fx -= weight * _wall_push(wall_half - px - human_radius, r0)
            fx += weight * _wall_push(px + wall_half - human_radius, r0)
            fy -= weight * _wall_push(wall_half - py - human_radius, r0)
            fy += weight * _wall_push(py + wall_half - human_radius, r0)
            # The robot, seen only now and then, as in the paper's environment.
            if avoid_robot_prob > 0.0:
                coin = uniform(seed, scenario_id[e], STREAM_AVOID_ROBOT, i, step_count[e], 0)
                if coin < avoid_robot_prob:
                    ox = px - robot_xy[e, 0]
                    oy = py - robot_xy[e, 1]
                    dist = norm(ox, oy)
                    if dist > 0.0:
                        mag = weight * _wall_push(dist - robot_radius - human_radius, r0)
                        fx += mag * ox / dist
                        fy += mag * oy / dist
            # Other humans.
            vix = human_speed[e, i] * human_heading[e, i, 0]
            viy = human_speed[e, i] * human_heading[e, i, 1]
            for j in range(num_humans):
                if j == i:
                    continue
                ex = human_xy[e, j, 0] - px
                ey = human_xy[e, j, 1] - py
                d_ij = norm(ex, ey)
                if d_ij > 0.0:
                    ex /= d_ij
                    ey /= d_ij
                dx = lam * (human_speed[e, j] * human_heading[e, j, 0] - vix) + ex
                dy = lam * (human_speed[e, j] * human_heading[e, j, 1] - viy) + ey
                dnorm = norm(dx, dy)
                b = gamma * dnorm
                if b == 0.0:
                    continue
                tx = dx / dnorm
                ty = dy / dnorm
                theta = math.acos(min(1.0, max(-1.0, ex * tx + ey * ty)))
                decay = math.exp(-d_ij / b)
                a_t = math.exp(-((n_prime * b * theta) ** 2))
                a_n = a_t if n == n_prime else math.exp(-((n * b * theta) ** 2))
                # The normal is e_ij turned left: (−e_y, e_x).
                fx -= weight * decay * (a_t * tx - a_n * ey)
                fy -= weight * decay * (a_t * ty + a_n * ex)
            vx = fx * dt
            vy = fy * dt
            speed = norm(vx, vy)
            if speed > max_speed:
                vx *= max_speed / speed
                vy *= max_speed / speed
            out[e, i, 0] = vx
            out[e, i, 1] = vy


@numba.njit(cache=True, error_model="numpy")
def move_humans(
    seed: int,
    scenario_id: np.ndarray,
    active: np.ndarray,
    velocity: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_goal: np.ndarray,
    human_goal_index: np.ndarray,
    robot_xy: np.ndarray,
    goal_xy: np.ndarray,
    speed_threshold: float,
    wall_half: float,
    spawn_half: float,
    human_radius: float,
    robot_radius: float,
    human_goal_radius: float,
    robot_goal_radius: float,
    dt: float,
) -> None:
    """Move every human of the ``active`` envs along ``velocity`` (N, H, 2) for one step.

    As in the paper's environment: speeds below ``speed_threshold`` become 0 and the heading
    follows the velocity (a zero velocity keeps the old heading). Humans are kept inside the
    walls (a wall is a hard boundary for the dynamics, not just a force). Once all have moved,
    each human (in order) within ``human_radius + human_goal_radius`` of its goal draws its next
    goal, keyed by the goal's index so the draw does not depend on when it happens, and redrawn
    while it touches a wall, the robot (``robot_xy``, its current position), a human, a human
    goal or the robot goal ``goal_xy`` (``scenario.redraw_human_goal``).
    """
    num_envs, num_humans = human_speed.shape
    limit = wall_half - human_radius
    reach = human_radius + human_goal_radius
    for e in range(num_envs):
        if not active[e]:
            continue
        for i in range(num_humans):
            vx = velocity[e, i, 0]
            vy = velocity[e, i, 1]
            speed = norm(vx, vy)
            if speed > 0.0:
                human_heading[e, i, 0] = vx / speed
                human_heading[e, i, 1] = vy / speed
            if speed < speed_threshold:
                speed = 0.0
            human_speed[e, i] = speed
            x = human_xy[e, i, 0] + speed * dt * human_heading[e, i, 0]
            y = human_xy[e, i, 1] + speed * dt * human_heading[e, i, 1]
            human_xy[e, i, 0] = min(limit, max(-limit, x))
            human_xy[e, i, 1] = min(limit, max(-limit, y))
        for i in range(num_humans):
            x = human_xy[e, i, 0]
            y = human_xy[e, i, 1]
            if norm(human_goal[e, i, 0] - x, human_goal[e, i, 1] - y) < reach:
                human_goal_index[e, i] += 1
                redraw_human_goal(
                    seed, scenario_id[e], e, i, human_goal_index[e, i], spawn_half,
                    human_goal_radius, wall_half, robot_xy, robot_radius, human_xy, human_radius,
                    human_goal, goal_xy, robot_goal_radius,
                )  # fmt: skip


class HumanDynamics:
    """Computes and applies the humans' step for a batch; holds reusable scratch arrays."""

    def __init__(self, params: EnvParams, num_envs: int) -> None:
        self.params = params
        h = params.num_humans
        self.obstacles = orca.room_obstacles(params.wall_half_size)
        self.orca_params = orca.OrcaParams(
            neighbor_dist=params.orca_neighbor_dist,
            max_neighbors=params.orca_max_neighbors,
            time_horizon=params.orca_time_horizon,
            time_horizon_obst=params.orca_time_horizon_obst,
            time_step=params.dt,
        )
        agents = h + (1 if params.orca_avoid_robot else 0)
        self._radius = np.full((num_envs, agents), params.human_radius)
        self._max_speed = np.full((num_envs, agents), params.human_max_speed)
        if params.orca_avoid_robot:
            self._radius[:, h] = params.robot_radius
            self._max_speed[:, h] = params.robot_max_speed
        self._velocity = np.zeros((num_envs, h, 2))

    def velocities(self, seed: int, state: BatchState) -> np.ndarray:
        """(N, H, 2) new velocities of every human (m/s), from the current snapshot."""
        p = self.params
        velocity = self._velocity
        velocity[:] = 0.0
        policies = state.human_policy
        if p.human_policy != "orca":
            sfm_velocities(
                seed,
                state.scenario_id,
                state.step_count,
                state.human_xy,
                state.human_heading,
                state.human_speed,
                state.human_goal,
                policies,
                state.robot_xy,
                p.wall_half_size,
                p.human_radius,
                p.robot_radius,
                p.human_max_speed,
                p.sfm_avoid_robot_prob,
                p.sfm_wall_range,
                p.sfm_gamma,
                p.sfm_n,
                p.sfm_n_prime,
                p.sfm_lambda,
                p.sfm_weight,
                p.dt,
                velocity,
            )
        if p.human_policy != "sfm":
            orca_v = self._orca(state)
            is_orca = (policies == POLICY_ORCA)[..., None]
            np.copyto(velocity, orca_v, where=is_orca)
        # A human moves speed·dt along its velocity, so this caps every displacement at
        # human_max_speed·dt. SFM clips its own velocity and ORCA's linear program keeps it in
        # the same circle; this final clip catches whatever gets past them (a no-op otherwise).
        speed = np.linalg.norm(velocity, axis=-1, keepdims=True)
        np.multiply(
            velocity, p.human_max_speed / np.maximum(speed, p.human_max_speed), out=velocity
        )
        return velocity

    def _orca(self, state: BatchState) -> np.ndarray:
        p = self.params
        h = p.num_humans
        position = state.human_xy
        current = state.human_velocity()
        to_goal = state.human_goal - position
        dist = np.linalg.norm(to_goal, axis=-1, keepdims=True)
        pref = np.divide(
            to_goal * p.human_max_speed, dist, out=np.zeros_like(to_goal), where=dist > 0
        )
        compute = state.human_policy == POLICY_ORCA
        if p.orca_avoid_robot:
            # The robot joins as an agent that does not reciprocate (compute=False).
            robot_v = state.robot_v[:, None] * np.stack(
                (np.cos(state.robot_theta), np.sin(state.robot_theta)), axis=-1
            )
            position = np.concatenate((position, state.robot_xy[:, None]), axis=1)
            current = np.concatenate((current, robot_v[:, None]), axis=1)
            pref = np.concatenate((pref, robot_v[:, None]), axis=1)
            compute = np.concatenate((compute, np.zeros((state.num_envs, 1), bool)), axis=1)
        new_v = orca.orca_velocities(
            position,
            current,
            pref,
            self._radius,
            self._max_speed,
            compute,
            self.obstacles,
            self.orca_params,
        )
        return new_v[:, :h]

    def move(self, seed: int, state: BatchState, velocity: np.ndarray, active: np.ndarray) -> None:
        p = self.params
        move_humans(
            seed,
            state.scenario_id,
            active,
            velocity,
            state.human_xy,
            state.human_heading,
            state.human_speed,
            state.human_goal,
            state.human_goal_index,
            state.robot_xy,
            state.goal_xy,
            p.human_speed_threshold,
            p.wall_half_size,
            p.spawn_half_size,
            p.human_radius,
            p.robot_radius,
            p.human_goal_radius,
            p.goal_radius,
            p.dt,
        )
