"""How well a world model predicts, in metres: k-step open-loop errors against the no-learning
predictors.

The setup is how a planner uses a model. Episodes of one scenario seed run under a policy and
are recorded. After ``warmup`` real steps (the models follow the real trajectory), each model is
rolled out open loop for ``k = 1…horizon`` steps with the actions that were really taken, and
its predicted goal and human positions are compared with the recorded observations: the
Euclidean error in metres, in the robot frame; with ``starts`` > 1 again from every
``horizon`` steps later, each a rollout of its own. A rollout counts at step ``k`` while its
episode was still running (the step that produced the observation was a real one). The humans'
errors are also split by what each human met in the window (:data:`INTERACTIONS`): the robot,
another human, its group, an obstacle, a new goal, or none of them: where a model wins or
loses against constant velocity.

Predictors: the three of :mod:`socnav_wm.worldmodel.ego` (``copy-last``, ``static``,
``constant-velocity``; the robot's own motion exact in the last two) and the paper's VAE + LSTM
(``vae-lstm``): the VAE encodes every real observation (its mean), the LSTM is teacher-forced
along the real trajectory up to the present, then fed its own predicted latents; each latent is
decoded by the VAE. Its ``k = 0`` error is the VAE's alone (decode(encode(obs))). With
planning models (:mod:`socnav_wm.worldmodel.residual`, one per training seed), ``planning-model``
is their mean over seeds, with the 95% interval over seeds, and ``planning_model`` compares them
with constant velocity: per seed the mean paired difference over episodes, then its mean and
95% interval over seeds (negative: the learned model is nearer the truth). The networks run in
float64 copies, so the errors do not depend on the batch size.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from socnav_wm.data.collect import PlannerFactory
from socnav_wm.env.core import NUM_ACTIONS, Simulator
from socnav_wm.env.obstacles import nearest_points
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.ego import PREDICTORS, positions, predict_positions
from socnav_wm.worldmodel.params import PredictionParams

MODEL_PREDICTOR = "vae-lstm"
"""The name of the paper's world model among the predictors."""
PLANNING_PREDICTOR = "planning-model"
"""The name of the planning world model (its mean over training seeds) among the predictors."""
RESOLUTION_M = 1e-3
"""A mean difference from constant velocity below this (m) is "no different", whatever its
interval: the positions come from float32 observations, and a model that is constant velocity
but for rounding (the speed cap on velocities estimated a hair above the top speed) differs by
micrometres identically on every seed, an interval of width zero."""

Policy = Callable[[np.ndarray, Simulator], np.ndarray]
"""``policy(obs (N, D), simulator) → actions (N,)``, called once per step for every episode (a
planner that imagines with the simulator reads it; the others read the observations)."""


@dataclass(frozen=True)
class Recording:
    """Episodes recorded step by step (finished ones carried along, their actions ignored).

    Attributes:
        obs: (T + 1, N, D) float64 observations, ``obs[t]`` after ``t`` steps.
        actions: (T, N) int64, ``actions[t]`` taken at step ``t``.
        stepped: (T, N) bool, step ``t`` was a real step of a running episode.
        goal_index: (T + 1, N, H) int64, how many goals each human had reached by ``obs[t]``
            (the simulator's count; not in the observation), or None.
        pose: (T + 1, N, 3) the robot's room pose (x, y, θ) at ``obs[t]`` (what a planning
            model that knows the room starts from), or None.
        scene: what each human met, for the split of the errors by interaction, or None.
    """

    obs: np.ndarray
    actions: np.ndarray
    stepped: np.ndarray
    goal_index: np.ndarray | None = None
    pose: np.ndarray | None = None
    scene: Scene | None = None


@dataclass(frozen=True)
class Scene:
    """The room-frame facts behind each human's motion (the simulator's; not in the
    observation).

    Attributes:
        human_xy: (T + 1, N, H, 2) the humans' positions at ``obs[t]`` (m).
        sees_robot: (N, H) the human reacts to the robot this episode.
        group: (N, H) the human's group, −1 alone.
        obstacles: the static map (kind (N, O), centres (N, O, 2), half sizes (N, O, 2)), or
            None when the scenarios have none.
    """

    human_xy: np.ndarray
    sees_robot: np.ndarray
    group: np.ndarray
    obstacles: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def record(
    env_params: EnvParams, policy: Policy, seed: int, scenario_ids: np.ndarray, steps: int
) -> Recording:
    """Run scenarios ``scenario_ids`` of ``seed`` for ``steps`` steps under ``policy``."""
    ids = np.asarray(scenario_ids, dtype=np.int64)
    sim = Simulator(len(ids), env_params)
    obs, _ = sim.reset(seed=seed, scenario_ids=ids)
    all_obs, actions, stepped = [np.asarray(obs, dtype=np.float64)], [], []
    state = sim.state
    goal_index = [state.human_goal_index.copy()]
    poses = [state.robot_pose()]
    human_xy = [state.human_xy.copy()]
    for _ in range(steps):
        running = ~state.done.copy()
        a = np.asarray(policy(obs, sim), dtype=np.int64)
        obs = sim.step(a).obs
        all_obs.append(np.asarray(obs, dtype=np.float64))
        goal_index.append(state.human_goal_index.copy())
        poses.append(state.robot_pose())
        human_xy.append(state.human_xy.copy())
        actions.append(a)
        stepped.append(running)
    obstacles = None
    if state.obstacle_kind.shape[1]:
        obstacles = (state.obstacle_kind.copy(), state.obstacle_xy.copy(),
                     state.obstacle_half.copy())  # fmt: skip
    scene = Scene(
        np.stack(human_xy), state.human_sees_robot.copy(), state.human_group.copy(), obstacles
    )
    return Recording(
        np.stack(all_obs),
        np.stack(actions),
        np.stack(stepped),
        np.stack(goal_index),
        np.stack(poses),
        scene,
    )


def random_policy(seed: int) -> Policy:
    """Uniform random actions from a generator of its own."""
    rng = np.random.default_rng(seed)
    return lambda obs, sim: rng.integers(0, NUM_ACTIONS, size=len(obs))


def epsilon_greedy(agent: Any, epsilon: float, seed: int) -> Policy:
    """A trained agent's greedy action, replaced by a uniform one with probability ``epsilon``.
    The agent's world-model state follows the actions really taken."""
    rng = np.random.default_rng(seed)
    features_of = agent.fresh_variant()
    last: list[np.ndarray] = []

    def act(obs: np.ndarray, sim: Simulator) -> np.ndarray:
        features = features_of.reset(obs) if not last else features_of.step(obs, last[0])[0]
        actions = _explore(rng, epsilon, agent.act(features).cpu().numpy())
        last[:] = [actions]
        return actions

    return act


def planner_epsilon_greedy(planner: PlannerFactory, epsilon: float, seed: int) -> Policy:
    """A planner's action (:data:`socnav_wm.data.collect.PlannerFactory`: one policy for the
    episodes, which start together), replaced by a uniform one with probability ``epsilon``."""
    rng = np.random.default_rng(seed)
    plan, reads_simulator = planner()

    def act(obs: np.ndarray, sim: Simulator) -> np.ndarray:
        return _explore(rng, epsilon, np.asarray(plan(sim if reads_simulator else obs)))

    return act


def _explore(rng: np.random.Generator, epsilon: float, chosen: np.ndarray) -> np.ndarray:
    """``chosen`` (N,) actions, each replaced by a uniform one with probability ``epsilon``
    (both draws made every step, whatever ``epsilon`` is)."""
    explore = rng.random(len(chosen)) < epsilon
    return np.where(explore, rng.integers(0, NUM_ACTIONS, size=len(chosen)), chosen)


def model_positions(
    vae: Any, lstm: Any, recording: Recording, start: int, horizon: int, batch_size: int
) -> tuple[np.ndarray, np.ndarray]:
    """The VAE + LSTM's positions: (N, 1 + H, 2) at ``k = 0`` (the VAE alone) and
    (N, horizon, 1 + H, 2) open loop from step ``start`` (see the module docstring)."""
    import torch

    vae = copy.deepcopy(vae).double().eval()
    lstm = copy.deepcopy(lstm).double().eval()
    n = recording.obs.shape[1]
    now = np.empty((n, *positions(recording.obs[0]).shape[1:]))
    ahead = np.empty((n, horizon, *now.shape[1:]))
    with torch.no_grad():
        for first in range(0, n, batch_size):
            rows = slice(first, first + batch_size)
            obs = torch.from_numpy(recording.obs[: start + 1, rows])  # (start + 1, b, D)
            actions = torch.from_numpy(recording.actions[:, rows])
            z = vae.encode(obs.reshape(-1, obs.shape[-1]))[0].reshape(*obs.shape[:2], -1)

            def decoded(latent: torch.Tensor) -> np.ndarray:
                return positions(vae.destandardize(vae.decode(latent)).numpy())

            now[rows] = decoded(z[start])
            state = None
            for t in range(start):  # teacher forcing along the real trajectory
                _, state = lstm.step(z[t], actions[t], state)
            latent = z[start]
            for k in range(horizon):
                latent, state = lstm.step(latent, actions[start + k], state)
                ahead[rows, k] = decoded(latent)
    return now, ahead


def _mean_ci(errors: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95% t-interval of a sample (NaN interval below two values)."""
    from scipy import stats

    n = errors.size
    if n == 0:
        return math.nan, math.nan, math.nan
    mean = float(errors.mean())
    if n < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.975, n - 1) * errors.std(ddof=1) / math.sqrt(n))
    return mean, mean - half, mean + half


def _summaries(errors: np.ndarray, valid: np.ndarray) -> dict[str, list[Any]]:
    """Per k: goal and humans (mean over humans) errors' means and intervals, over the valid
    episodes; ``errors`` (N, K, 1 + H), ``valid`` (N, K)."""
    out: dict[str, list[Any]] = {"goal": [], "goal_ci": [], "humans": [], "humans_ci": []}
    for k in range(errors.shape[1]):
        rows = valid[:, k]
        for name, values in (
            ("goal", errors[rows, k, 0]),
            ("humans", errors[rows, k, 1:].mean(axis=-1)),
        ):
            mean, low, high = _mean_ci(values)
            out[name].append(mean)
            out[f"{name}_ci"].append([low, high])
    return out


def _by_goal_change(
    errors_of: Mapping[str, np.ndarray], valid: np.ndarray, changed: np.ndarray
) -> dict[str, Any]:
    """Per k: the share of humans who drew a new goal between the velocity's first view
    (``t0 − 1``) and ``t0 + k`` (``changed`` (N, K, H); their turn cannot be foreseen: goals are
    not observed), and each predictor's humans' error (``errors_of``: (N, K, 1 + H) each) over
    those who kept their goal and over those who did not."""
    horizon = valid.shape[1]
    out: dict[str, Any] = {"changed_share": [], "predictors": {}}
    for k in range(horizon):
        out["changed_share"].append(float(changed[valid[:, k], k].mean()))
    for name, all_errors in errors_of.items():
        errors = all_errors[..., 1:]  # (N, K, H)
        kept, new = [], []
        for k in range(horizon):
            e, c = errors[valid[:, k], k], changed[valid[:, k], k]
            kept.append(float(e[~c].mean()) if (~c).any() else math.nan)
            new.append(float(e[c].mean()) if c.any() else math.nan)
        out["predictors"][name] = {"kept": kept, "changed": new}
    return out


def _by_interaction(
    errors_of: Mapping[str, np.ndarray],
    valid: np.ndarray,
    met: Mapping[str, np.ndarray],
    distance: float,
) -> dict[str, Any]:
    """Per interaction and k: the share of humans who met it, each predictor's mean humans'
    error over them (NaN where none did) and, with the planning model, its paired difference
    from constant velocity: per rollout the mean over its humans who met it, then the mean
    and 95% t-interval over the rollouts that have one (a human's neighbours in one rollout
    are not independent samples)."""
    horizon = valid.shape[1]
    out: dict[str, Any] = {"distance": distance, "near": list(NEAR), "share": {}, "predictors": {}}
    for name, label in met.items():
        out["share"][name] = [float(label[valid[:, k], k].mean()) for k in range(horizon)]
    for predictor, errors in errors_of.items():
        humans = errors[..., 1:]
        out["predictors"][predictor] = {
            name: [
                float(humans[valid[:, k], k][label[valid[:, k], k]].mean())
                if label[valid[:, k], k].any() else math.nan
                for k in range(horizon)
            ]
            for name, label in met.items()
        }  # fmt: skip
    if PLANNING_PREDICTOR in errors_of:
        gain = errors_of[PLANNING_PREDICTOR][..., 1:] - errors_of["constant-velocity"][..., 1:]
        versus: dict[str, Any] = {}
        for name, label in met.items():
            rows: dict[str, list[Any]] = {"difference": [], "difference_ci": [], "rollouts": []}
            for k in range(horizon):
                chosen = label[:, k] & valid[:, k, None]  # (N, H)
                count = chosen.sum(axis=1)
                has = count > 0
                per_rollout = (gain[:, k] * chosen).sum(axis=1)[has] / count[has]
                mean, low, high = _mean_ci(per_rollout)
                rows["difference"].append(mean)
                rows["difference_ci"].append([low, high])
                rows["rollouts"].append(int(has.sum()))
            versus[name] = rows
        out["planning_model"] = versus
    return out


def _over_seeds(per_seed: Sequence[np.ndarray], valid: np.ndarray) -> dict[str, list[Any]]:
    """Per k: the mean over seeds of each seed's mean error (goal; humans), with the 95%
    t-interval over seeds."""
    out: dict[str, list[Any]] = {"goal": [], "goal_ci": [], "humans": [], "humans_ci": []}
    for k in range(valid.shape[1]):
        rows = valid[:, k]
        for name, part in (("goal", slice(0, 1)), ("humans", slice(1, None))):
            means = np.array([e[rows, k, part].mean() for e in per_seed])
            mean, low, high = _mean_ci(means)
            out[name].append(mean)
            out[f"{name}_ci"].append([low, high])
    return out


def _versus_constant_velocity(
    per_seed: Sequence[np.ndarray], cv: np.ndarray, valid: np.ndarray
) -> dict[str, Any]:
    """Per k: each seed's humans' error, its mean paired difference from constant velocity over
    episodes, and the difference's mean and 95% interval over seeds with a verdict."""
    out: dict[str, Any] = {"seeds": len(per_seed), "humans_per_seed": [], "difference": []}
    out.update({"difference_ci": [], "verdict": []})
    for k in range(valid.shape[1]):
        rows = valid[:, k]
        humans = [float(e[rows, k, 1:].mean()) for e in per_seed]
        if len(per_seed) == 1:  # one seed: the interval over episodes of its paired difference
            mean, low, high = _mean_ci((per_seed[0][rows, k, 1:] - cv[rows, k, 1:]).mean(-1))
        else:
            differences = [(e[rows, k, 1:] - cv[rows, k, 1:]).mean() for e in per_seed]
            mean, low, high = _mean_ci(np.array(differences))
        verdict = "better" if high < 0 else "worse" if low > 0 else "no different"
        if math.isnan(low):
            verdict = "better" if mean < 0 else "worse" if mean > 0 else "no different"
        if abs(mean) < RESOLUTION_M:
            verdict = "no different"
        out["humans_per_seed"].append(humans)
        out["difference"].append(mean)
        out["difference_ci"].append([low, high])
        out["verdict"].append(verdict)
    return out


INTERACTIONS = ("robot", "humans", "group", "obstacle", "goal change", "none")
"""What a human met in a window (a human may meet several; ``none``: none of the others):
the robot it sees, another human, its group (it belongs to one), an obstacle (each within
``prediction.interaction_distance`` at some step), and a new goal drawn."""
NEAR = ("robot", "humans", "obstacle")
"""The interactions that are a meeting within ``prediction.interaction_distance``."""


@dataclass(frozen=True)
class _Window:
    """One open-loop rollout per episode from one start step: every array's first axis is the
    episode (windows of several starts are concatenated along it)."""

    truth: np.ndarray  # (N, K, 1 + H, 2)
    valid: np.ndarray  # (N, K)
    predicted: dict[str, np.ndarray]  # name → (N, K, 1 + H, 2)
    per_seed: list[np.ndarray]  # the planning models' errors, each (N, K, 1 + H)
    now: np.ndarray | None  # (N, 1 + H) the VAE's error alone (decode(encode(obs))) at the start
    changed: np.ndarray | None  # (N, K, H) drew a new goal since the velocity's first view
    met: dict[str, np.ndarray] | None  # interaction → (N, K, H)

    @staticmethod
    def joined(windows: Sequence[_Window]) -> _Window:
        def cat(parts: Sequence[Any]) -> Any:
            return None if parts[0] is None else np.concatenate(parts)

        first = windows[0]
        return _Window(
            cat([w.truth for w in windows]),
            cat([w.valid for w in windows]),
            {n: cat([w.predicted[n] for w in windows]) for n in first.predicted},
            [cat([w.per_seed[i] for w in windows]) for i in range(len(first.per_seed))],
            cat([w.now for w in windows]),
            cat([w.changed for w in windows]),
            None if first.met is None else {
                name: cat([w.met[name] for w in windows]) for name in first.met  # type: ignore[index]
            },
        )  # fmt: skip


def _met(
    scene: Scene, pose: np.ndarray, changed: np.ndarray, t0: int, horizon: int, distance: float
) -> dict[str, np.ndarray]:
    """Per interaction (:data:`INTERACTIONS`), whether each human met it between ``obs[t0]``
    and ``obs[t0 + k]``: (N, K, H) each."""
    steps = range(t0, t0 + horizon + 1)
    humans = scene.human_xy[t0 : t0 + horizon + 1]  # (K + 1, N, H, 2)
    robot = pose[t0 : t0 + horizon + 1, :, None, :2]
    near_robot = (np.linalg.norm(humans - robot, axis=-1) <= distance) & scene.sees_robot
    gaps = np.linalg.norm(humans[:, :, :, None] - humans[:, :, None], axis=-1)
    num_humans = gaps.shape[-1]
    gaps[..., np.arange(num_humans), np.arange(num_humans)] = np.inf
    near_human = gaps.min(axis=-1) <= distance
    near_obstacle = np.zeros_like(near_human)
    if scene.obstacles is not None:
        n = scene.obstacles[0].shape[0]
        # Each human against its episode's map: the map once per human, env-major.
        per_human = [np.repeat(a, num_humans, axis=0) for a in scene.obstacles]
        for i, t in enumerate(steps):
            _, gap = nearest_points(scene.human_xy[t].reshape(-1, 2), *per_human)
            near_obstacle[i] = (gap.min(axis=-1) <= distance).reshape(n, num_humans)

    def so_far(near: np.ndarray) -> np.ndarray:  # (K + 1, N, H) → met by obs[t0 + k]
        return np.logical_or.accumulate(near, axis=0)[1:].transpose(1, 0, 2)

    met = {
        "robot": so_far(near_robot),
        "humans": so_far(near_human),
        "group": np.broadcast_to(scene.group[:, None] >= 0, changed.shape),
        "obstacle": so_far(near_obstacle),
        "goal change": changed,
    }
    met["none"] = ~np.logical_or.reduce(list(met.values()))
    return met


def _window(
    recording: Recording,
    env_params: EnvParams,
    t0: int,
    horizon: int,
    distance: float,
    world_model: tuple[Any, Any] | None,
    planning_models: Sequence[Any],
    batch_size: int,
) -> _Window:
    """Every predictor's positions open loop from ``obs[t0]``, and what the humans met."""
    truth = np.stack(
        [positions(recording.obs[t0 + k]) for k in range(1, horizon + 1)], axis=1
    )  # (N, K, 1 + H, 2)
    # Observation t0 + k is real when every step t0 … t0 + k − 1 was (and t0 − 1, for the
    # velocity): an episode that ended earlier is carried along frozen.
    valid = np.logical_and.accumulate(recording.stepped[t0 - 1 : t0 + horizon], axis=0)[1:].T
    future = recording.actions[t0 : t0 + horizon].T
    start = (recording.obs[t0 - 1], recording.obs[t0], recording.actions[t0 - 1])
    predicted = {name: predict_positions(name, *start, future, env_params) for name in PREDICTORS}
    now = None
    if world_model is not None:
        decoded, predicted[MODEL_PREDICTOR] = model_positions(
            *world_model, recording, t0, horizon, batch_size
        )
        now = np.linalg.norm(decoded - positions(recording.obs[t0]), axis=-1)
    per_seed = []
    if planning_models:
        from socnav_wm.worldmodel.residual import residual_positions

        pose = None if recording.pose is None else recording.pose[t0]
        per_seed = [
            np.linalg.norm(
                residual_positions(m, *start, future, env_params, pose=pose) - truth, axis=-1
            )
            for m in planning_models
        ]  # each (N, K, 1 + H)
    changed = met = None
    if recording.goal_index is not None:
        index = recording.goal_index
        changed = np.stack(
            [index[t0 + k] != index[t0 - 1] for k in range(1, horizon + 1)], axis=1
        )  # (N, K, H)
        if recording.scene is not None and recording.pose is not None:
            met = _met(recording.scene, recording.pose, changed, t0, horizon, distance)
    return _Window(truth, valid, predicted, per_seed, now, changed, met)


def prediction_errors(
    recording: Recording,
    env_params: EnvParams,
    params: PredictionParams,
    *,
    world_model: tuple[Any, Any] | None = None,
    planning_models: Sequence[Any] = (),
    batch_size: int,
) -> dict[str, Any]:
    """k-step errors (m) of every predictor on a recording, from ``params.starts`` start
    steps per episode (``params.warmup``, then every ``params.horizon`` steps).

    Returns ``{"k": [1…horizon], "n": [rollouts counted at each k], "predictors": {name:
    {"goal", "goal_ci", "humans", "humans_ci"}}}``; the model's entry (with ``world_model =
    (vae, lstm)``) also has ``"k0": {"goal", "humans"}``, the VAE's own error. With
    ``planning_models`` (one per training seed), ``"planning_model"`` holds per k the seeds'
    humans' errors and the difference from constant velocity (module docstring). A recording
    with the simulator's facts adds ``"goal_change"`` and ``"interactions"`` (the humans' errors
    by what they met, :data:`INTERACTIONS`).
    """
    warmup, horizon = params.warmup, params.horizon
    needed = warmup + params.starts * horizon
    if recording.actions.shape[0] < needed:
        raise ValueError(
            f"the recording has {recording.actions.shape[0]} steps, "
            f"warmup + starts × horizon needs {needed}"
        )
    w = _Window.joined(
        [
            _window(recording, env_params, warmup + j * horizon, horizon,
                    params.interaction_distance, world_model, planning_models, batch_size)
            for j in range(params.starts)
        ]
    )  # fmt: skip
    valid = w.valid
    result: dict[str, Any] = {
        "k": list(range(1, horizon + 1)),
        "n": valid.sum(axis=0).tolist(),
        "predictors": {},
    }
    errors_of = {n: np.linalg.norm(p - w.truth, axis=-1) for n, p in w.predicted.items()}
    for name, errors in errors_of.items():
        result["predictors"][name] = _summaries(errors, valid)
    if w.per_seed:
        cv = errors_of["constant-velocity"]
        result["predictors"][PLANNING_PREDICTOR] = _over_seeds(w.per_seed, valid)
        result["planning_model"] = _versus_constant_velocity(w.per_seed, cv, valid)
        errors_of[PLANNING_PREDICTOR] = np.mean(w.per_seed, axis=0)
    if w.changed is not None:
        result["goal_change"] = _by_goal_change(errors_of, valid, w.changed)
    if w.met is not None:
        result["interactions"] = _by_interaction(
            errors_of, valid, w.met, params.interaction_distance
        )
    if w.now is not None:
        present = valid[:, 0]
        error_now = w.now[present]
        result["predictors"][MODEL_PREDICTOR]["k0"] = {
            "goal": float(error_now[:, 0].mean()),
            "humans": float(error_now[:, 1:].mean()),
        }
    return result


def error_table(errors: Mapping[str, Any], ks: Sequence[int] = (1, 4, 8, 12, 16)) -> list[dict]:
    """Rows ``{"k", "<predictor> goal", "<predictor> humans", …}`` at the chosen ``k``."""
    rows = []
    for k in ks:
        if k not in errors["k"]:
            continue
        i = errors["k"].index(k)
        row: dict[str, Any] = {"k": k, "n": errors["n"][i]}
        for name, values in errors["predictors"].items():
            row[f"{name} goal"] = values["goal"][i]
            row[f"{name} humans"] = values["humans"][i]
        rows.append(row)
    return rows


def evaluate_prediction(
    env_params: EnvParams,
    params: PredictionParams,
    *,
    world_model: tuple[Any, Any] | None,
    agent: Any | None,
    planner: tuple[str, PlannerFactory] | None = None,
    planning_models: Sequence[Any] = (),
    batch_size: int = 512,
) -> dict[str, Any]:
    """The errors of every predictor (``planning_models``: the planning world model's seeds)
    under the random policy and, with ``agent``, under its ε-greedy policy, and with
    ``planner`` (its name and policies), under the planner's ε-greedy one: ``{"settings": {…},
    "policies": {"random": …, "agent": …, <planner>: …}}``, each policy's entry as
    :func:`prediction_errors` returns it. Every policy runs scenarios ``0..episodes−1`` of
    ``scenario_seed`` (``params``: the ``prediction`` section)."""
    episodes, scenario_seed, epsilon = params.episodes, params.scenario_seed, params.epsilon
    ids = np.arange(episodes)
    policies: dict[str, Policy] = {"random": random_policy(scenario_seed)}
    if agent is not None:
        policies["agent"] = epsilon_greedy(agent, epsilon, scenario_seed)
    if planner is not None:
        policies[planner[0]] = planner_epsilon_greedy(planner[1], epsilon, scenario_seed)
    result: dict[str, Any] = {
        "settings": {
            "episodes": episodes,
            "scenario_seed": scenario_seed,
            "warmup": params.warmup,
            "horizon": params.horizon,
            "starts": params.starts,
            "interaction_distance": params.interaction_distance,
            "epsilon": epsilon,
            "agent": None if agent is None else agent.variant_name,
            "planner": None if planner is None else planner[0],
            "planning_model_seeds": len(planning_models),
        },
        "policies": {},
    }
    steps = params.warmup + params.starts * params.horizon
    for name, policy in policies.items():
        recording = record(env_params, policy, scenario_seed, ids, steps)
        result["policies"][name] = prediction_errors(
            recording, env_params, params, world_model=world_model,
            planning_models=planning_models, batch_size=batch_size,
        )  # fmt: skip
    return result
