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
from socnav_wm.env.draws import STREAM_AVOID_ROBOT, uniform
from socnav_wm.env.geometry import norm
from socnav_wm.env.groups import group_pull
from socnav_wm.env.obstacles import polygon_sizes, polygons, push_out, slot_nearest_point
from socnav_wm.env.params import PAPER_SFM_SEES_ROBOT, EnvParams
from socnav_wm.env.scenario import (
    FAMILY_CODES,
    POLICY_ORCA,
    POLICY_SFM,
    SEES_ALWAYS,
    SEES_CODES,
    SEES_PAPER,
    redraw_human_goal,
)
from socnav_wm.env.state import OBSTACLE_NONE, BatchState

ORCA_KEEP_RIGHT = 0.02
"""rad: how far to the right an ORCA human who sees the robot turns its preferred velocity."""

# exp(-x) below exp(-40) ≈ 4e-18 is lost next to the desired force (≈ 0.08): skip the call.
_EXP_CUTOFF = 40.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def _wall_push(gap: float, r0: float) -> float:
    """exp(−gap/r0), the paper's obstacle repulsion, skipped where it underflows."""
    x = gap / r0
    return math.exp(-x) if x < _EXP_CUTOFF else 0.0


@numba.njit(cache=True, error_model="numpy", inline="always")
def _moves(e: int, i: int, human_policy: np.ndarray, still: np.ndarray, grouped: bool) -> bool:
    """Whether human i of env e moves by the social force (an SFM human not standing still)."""
    return human_policy[e, i] == POLICY_SFM and not (grouped and still[e, i])


@numba.njit(cache=True, error_model="numpy")
def _pair_forces(
    e: int,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_policy: np.ndarray,
    still: np.ndarray,
    grouped: bool,
    gamma: float,
    n: float,
    n_prime: float,
    lam: float,
    weight: float,
    pair: np.ndarray,
    pair_ok: np.ndarray,
) -> None:
    """The interaction force ``pair[i, j]`` (subtracted from i's force) of every pair of env e
    in which a human moves by the social force, and ``pair_ok[i, j]`` where it applies.

    Each pair is computed once: swapping i and j negates e_ij and the velocity difference, so
    the interaction direction t, the normal and the force change sign while d_ij, B, θ and the
    exponentials stay the same. In IEEE arithmetic a − b = −(b − a) and (−a)·b = −(a·b) exactly,
    so ``pair[j, i] = −pair[i, j]`` is bit for bit what computing it from j's side gives.
    """
    num_humans = human_speed.shape[1]
    for i in range(num_humans):
        moves_i = _moves(e, i, human_policy, still, grouped)
        px = human_xy[e, i, 0]
        py = human_xy[e, i, 1]
        vix = human_speed[e, i] * human_heading[e, i, 0]
        viy = human_speed[e, i] * human_heading[e, i, 1]
        for j in range(i + 1, num_humans):
            if not (moves_i or _moves(e, j, human_policy, still, grouped)):
                pair_ok[i, j] = False
                pair_ok[j, i] = False
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
            ok = b != 0.0
            pair_ok[i, j] = ok
            pair_ok[j, i] = ok
            if not ok:
                continue
            tx = dx / dnorm
            ty = dy / dnorm
            theta = math.acos(min(1.0, max(-1.0, ex * tx + ey * ty)))
            decay = math.exp(-d_ij / b)
            a_t = math.exp(-((n_prime * b * theta) ** 2))
            a_n = a_t if n == n_prime else math.exp(-((n * b * theta) ** 2))
            # The normal is e_ij turned left: (−e_y, e_x).
            fx = weight * decay * (a_t * tx - a_n * ey)
            fy = weight * decay * (a_t * ty + a_n * ex)
            pair[i, j, 0] = fx
            pair[i, j, 1] = fy
            pair[j, i, 0] = -fx
            pair[j, i, 1] = -fy


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
    human_max_speed: np.ndarray,
    human_sees_robot: np.ndarray,
    robot_xy: np.ndarray,
    sees_mode: int,
    stay_at_goal: bool,
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
    still: np.ndarray,
    pull: np.ndarray,
    grouped: bool,
    wall_half: float,
    human_radius: float,
    robot_radius: float,
    avoid_robot_prob: float,
    robot_strength: float,
    robot_range: float,
    robot_side: float,
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
    exponential repulsion ``exp(−d/r0)·e_o`` from each wall and each obstacle (from its
    nearest point), and the Moussaïd-style interaction force of every other human; each term
    weighted by ``weight``. Velocity = force/m·dt, m = 1, capped at the human's ``max_speed``.
    The robot (``sees_mode``): ``SEES_PAPER``, it pushes as a wall with probability
    ``avoid_robot_prob`` per human per step; ``SEES_ALWAYS``, a human that sees it
    (``human_sees_robot``) is pushed away from it, ``robot_strength·exp(−gap/robot_range)``
    (gap surface to surface), plus ``robot_side`` times that to its right in proportion to how
    squarely the robot stands between it and its goal. With
    ``stay_at_goal`` (the crossing families) the desired speed falls to ``dist/1 s`` within a
    metre of the goal, as CrowdNav's humans slow down there. With ``grouped``, a walking-group
    member adds ``max_speed·pull`` (:func:`group_pull`), and a ``still`` human (a standing
    group's) does not move.
    """
    num_envs, num_humans = human_speed.shape
    pair = np.empty((num_humans, num_humans, 2))
    pair_ok = np.zeros((num_humans, num_humans), dtype=np.bool_)
    for e in range(num_envs):
        _pair_forces(
            e, human_xy, human_heading, human_speed, human_policy, still, grouped, gamma, n,
            n_prime, lam, weight, pair, pair_ok,
        )  # fmt: skip
        for i in range(num_humans):
            if human_policy[e, i] != POLICY_SFM:
                continue
            if grouped and still[e, i]:
                out[e, i, 0] = 0.0
                out[e, i, 1] = 0.0
                continue
            px = human_xy[e, i, 0]
            py = human_xy[e, i, 1]
            # Desired force towards the goal at full speed.
            gx = human_goal[e, i, 0] - px
            gy = human_goal[e, i, 1] - py
            gnorm = norm(gx, gy)
            max_speed = human_max_speed[e, i]
            desired = min(max_speed, gnorm) if stay_at_goal else max_speed
            fx = 0.0
            fy = 0.0
            if gnorm > 0.0:
                fx = weight * desired * gx / gnorm
                fy = weight * desired * gy / gnorm
            if grouped:
                fx += weight * max_speed * pull[e, i, 0]
                fy += weight * max_speed * pull[e, i, 1]
            # Walls: the nearest point of each wall is on its inner face.
            fx -= weight * _wall_push(wall_half - px - human_radius, r0)
            fx += weight * _wall_push(px + wall_half - human_radius, r0)
            fy -= weight * _wall_push(wall_half - py - human_radius, r0)
            fy += weight * _wall_push(py + wall_half - human_radius, r0)
            # Obstacles: from the nearest point of each outline.
            for o in range(obstacle_kind.shape[1]):
                if obstacle_kind[e, o] == OBSTACLE_NONE:
                    continue
                qx, qy, d = slot_nearest_point(
                    px, py, e, o, obstacle_kind, obstacle_xy, obstacle_half
                )
                if d > 0.0:
                    mag = weight * _wall_push(d - human_radius, r0)
                    fx += mag * (px - qx) / d
                    fy += mag * (py - qy) / d
            # A human who sees the robot: pushed away from it and, when it stands between the
            # human and its goal, to the human's right (it steps round it).
            if sees_mode == SEES_ALWAYS and human_sees_robot[e, i] and gnorm > 0.0:
                ox = px - robot_xy[e, 0]
                oy = py - robot_xy[e, 1]
                dist = norm(ox, oy)
                if dist > 0.0:
                    nx = ox / dist
                    ny = oy / dist
                    ux = gx / gnorm
                    uy = gy / gnorm
                    ahead = max(0.0, -(nx * ux + ny * uy))
                    gap = dist - robot_radius - human_radius
                    mag = weight * robot_strength * math.exp(-gap / robot_range)
                    fx += mag * (nx + robot_side * ahead * uy)
                    fy += mag * (ny - robot_side * ahead * ux)
            # The robot, seen only now and then, as in the paper's environment.
            if sees_mode == SEES_PAPER and avoid_robot_prob > 0.0:
                coin = uniform(seed, scenario_id[e], STREAM_AVOID_ROBOT, i, step_count[e], 0)
                if coin < avoid_robot_prob:
                    ox = px - robot_xy[e, 0]
                    oy = py - robot_xy[e, 1]
                    dist = norm(ox, oy)
                    if dist > 0.0:
                        mag = weight * _wall_push(dist - robot_radius - human_radius, r0)
                        fx += mag * ox / dist
                        fy += mag * oy / dist
            # Other humans: the pair forces of this env (computed once per pair, below).
            for j in range(num_humans):
                if j != i and pair_ok[i, j]:
                    fx -= pair[i, j, 0]
                    fy -= pair[i, j, 1]
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
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
    human_group: np.ndarray,
    group_leader: np.ndarray,
    group_standing: np.ndarray,
    stay_at_goal: bool,
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
    walls and out of the obstacles (hard boundaries for the dynamics, not just forces; a human
    pushed out of an obstacle keeps its speed for the step). With ``stay_at_goal`` (the
    crossing families) goals never change. A standing group's members never move; a walking
    group's leader draws the group's next goal, which its members then share. Otherwise, once
    all have moved,
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
            group = human_group[e, i]
            if group >= 0 and group_standing[e, group]:
                human_speed[e, i] = 0.0
                continue
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
            if obstacle_kind.shape[1]:
                push_out(e, i, human_xy, human_radius, obstacle_kind, obstacle_xy, obstacle_half)
        if stay_at_goal:
            continue
        for i in range(num_humans):
            group = human_group[e, i]
            if group >= 0 and (group_standing[e, group] or group_leader[e, group] != i):
                continue  # a standing member, or a member who follows its leader's goal
            x = human_xy[e, i, 0]
            y = human_xy[e, i, 1]
            if norm(human_goal[e, i, 0] - x, human_goal[e, i, 1] - y) < reach:
                human_goal_index[e, i] += 1
                redraw_human_goal(
                    seed, scenario_id[e], e, i, human_goal_index[e, i], spawn_half,
                    human_goal_radius, wall_half, robot_xy, robot_radius, human_xy, human_radius,
                    human_goal, goal_xy, robot_goal_radius, obstacle_kind, obstacle_xy,
                    obstacle_half,
                )  # fmt: skip
                if group >= 0:
                    for j in range(num_humans):
                        if human_group[e, j] == group:
                            human_goal[e, j, 0] = human_goal[e, i, 0]
                            human_goal[e, j, 1] = human_goal[e, i, 1]


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
        self.sees_mode = SEES_CODES[params.humans_see_robot]
        self.stay_at_goal = FAMILY_CODES[params.scenario] != 0
        # ORCA humans who may see the robot: it joins as a last agent that does not reciprocate.
        self.robot_agent = self.sees_mode == SEES_ALWAYS
        agents = h + (1 if self.robot_agent else 0)
        self._radius = np.full((num_envs, agents), params.human_radius + params.orca_safety)
        if self.robot_agent:
            self._radius[:, h] = params.robot_radius + params.orca_safety
        self._velocity = np.zeros((num_envs, h, 2))
        self._env_obstacles: orca.EnvObstacles | None = None
        self.grouped = params.max_groups > 0
        self._pull = np.zeros((num_envs, h, 2))
        self._still = np.zeros((num_envs, h), dtype=bool)

    def reset_obstacles(self, state: BatchState, envs: np.ndarray | None = None) -> None:
        """Rebuild the ORCA polygons of the tables and plants of slots ``envs`` (default: all),
        after they were reset."""
        if state.obstacle_kind.shape[1] == 0:
            return
        rows = slice(None) if envs is None or self._env_obstacles is None else envs
        kind = state.obstacle_kind[rows]
        built = orca.EnvObstacles.from_polygons(
            polygons(kind, state.obstacle_xy[rows], state.obstacle_half[rows]),
            polygon_sizes(kind),
        )
        if isinstance(rows, slice):
            self._env_obstacles = built
            return
        for name in ("point", "next_index", "unit_dir", "is_convex", "count"):
            getattr(self._env_obstacles, name)[rows] = getattr(built, name)

    def velocities(self, seed: int, state: BatchState) -> np.ndarray:
        """(N, H, 2) new velocities of every human (m/s), from the current snapshot."""
        p = self.params
        velocity = self._velocity
        velocity[:] = 0.0
        policies = state.human_policy
        still = self._still
        if self.grouped:
            group_pull(state.human_xy, state.human_group, state.group_leader,
                       state.group_standing, self._pull)  # fmt: skip
            standing = np.take_along_axis(
                state.group_standing, np.maximum(state.human_group, 0), axis=1
            )
            still = (state.human_group >= 0) & standing
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
                state.human_max_speed,
                state.human_sees_robot,
                state.robot_xy,
                self.sees_mode,
                self.stay_at_goal,
                state.obstacle_kind,
                state.obstacle_xy,
                state.obstacle_half,
                still,
                self._pull,
                self.grouped,
                p.wall_half_size,
                p.human_radius,
                p.robot_radius,
                PAPER_SFM_SEES_ROBOT,
                p.sfm_robot_strength,
                p.sfm_robot_range,
                p.sfm_robot_side,
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
            orca_v = self._orca(state, still)
            is_orca = (policies == POLICY_ORCA)[..., None]
            np.copyto(velocity, orca_v, where=is_orca)
        # A human moves speed·dt along its velocity, so this caps every displacement at its
        # max speed·dt. SFM clips its own velocity and ORCA's linear program keeps it in the
        # same circle; this final clip catches whatever gets past them (a no-op otherwise).
        speed = np.linalg.norm(velocity, axis=-1, keepdims=True)
        limit = state.human_max_speed[..., None]
        np.multiply(velocity, limit / np.maximum(speed, limit), out=velocity)
        return velocity

    def _orca(self, state: BatchState, still: np.ndarray) -> np.ndarray:
        p = self.params
        h = p.num_humans
        position = state.human_xy
        current = state.human_velocity()
        to_goal = state.human_goal - position
        dist = np.linalg.norm(to_goal, axis=-1, keepdims=True)
        speed = state.human_max_speed[..., None]
        if self.stay_at_goal:  # CrowdNav's: the unit direction, the offset itself within 1 m
            speed = np.minimum(speed, dist)
        pref = np.divide(to_goal * speed, dist, out=np.zeros_like(to_goal), where=dist > 0)
        compute = state.human_policy == POLICY_ORCA
        if self.grouped:  # towards the goal and, beyond the threshold, back to the group
            pref = pref + self._pull * state.human_max_speed[..., None]
            length = np.linalg.norm(pref, axis=-1, keepdims=True)
            limit = state.human_max_speed[..., None]
            pref = pref * (limit / np.maximum(length, limit))
            compute = compute & ~still  # a standing member stays (a still neighbour to others)
        max_speed = state.human_max_speed
        blind = None
        if self.robot_agent:
            # Those who see the robot keep right: their preferred velocity turns by
            # ORCA_KEEP_RIGHT, breaking the exact symmetry of a head-on meeting, where ORCA only
            # slows down (RVO2's examples perturb it at random).
            c, s = math.cos(ORCA_KEEP_RIGHT), math.sin(ORCA_KEEP_RIGHT)
            turned = np.stack(
                (c * pref[..., 0] + s * pref[..., 1], -s * pref[..., 0] + c * pref[..., 1]),
                axis=-1,
            )
            pref = np.where(state.human_sees_robot[..., None], turned, pref)
            # The robot joins as an agent that does not reciprocate (compute=False, the humans
            # take all of the avoidance), unseen by the humans who ignore it.
            robot_v = state.robot_velocity()
            position = np.concatenate((position, state.robot_xy[:, None]), axis=1)
            current = np.concatenate((current, robot_v[:, None]), axis=1)
            pref = np.concatenate((pref, robot_v[:, None]), axis=1)
            compute = np.concatenate((compute, np.zeros((state.num_envs, 1), bool)), axis=1)
            max_speed = np.concatenate(
                (max_speed, np.full((state.num_envs, 1), p.robot_max_speed)), axis=1
            )
            blind = np.concatenate(
                (~state.human_sees_robot, np.ones((state.num_envs, 1), bool)), axis=1
            )
        new_v = orca.orca_velocities(
            position,
            current,
            pref,
            self._radius,
            max_speed,
            compute,
            self.obstacles,
            self.orca_params,
            self._env_obstacles,
            blind,
            self.robot_agent,
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
            state.obstacle_kind,
            state.obstacle_xy,
            state.obstacle_half,
            state.human_group,
            state.group_leader,
            state.group_standing,
            self.stay_at_goal,
            p.human_speed_threshold,
            p.wall_half_size,
            p.spawn_half_size,
            p.human_radius,
            p.robot_radius,
            p.human_goal_radius,
            p.goal_radius,
            p.dt,
        )
