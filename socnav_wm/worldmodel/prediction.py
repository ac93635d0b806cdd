"""How well a world model predicts, in metres: k-step open-loop errors against the no-learning
predictors.

The setup is how a planner uses a model. Episodes of one scenario seed run under a policy and
are recorded. After ``warmup`` real steps (the models follow the real trajectory), each model is
rolled out open loop for ``k = 1…horizon`` steps with the actions that were really taken, and
its predicted goal and human positions are compared with the recorded observations: the
Euclidean error in metres, in the robot frame. An episode counts at step ``k`` while it was
still running (the step that produced the observation was a real one).

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

from socnav_wm.env.core import NUM_ACTIONS, Simulator
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

Policy = Callable[[np.ndarray], np.ndarray]
"""``policy(obs (N, D)) → actions (N,)``, called once per step for every episode."""


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
    """

    obs: np.ndarray
    actions: np.ndarray
    stepped: np.ndarray
    goal_index: np.ndarray | None = None
    pose: np.ndarray | None = None


def record(
    env_params: EnvParams, policy: Policy, seed: int, scenario_ids: np.ndarray, steps: int
) -> Recording:
    """Run scenarios ``scenario_ids`` of ``seed`` for ``steps`` steps under ``policy``."""
    ids = np.asarray(scenario_ids, dtype=np.int64)
    sim = Simulator(len(ids), env_params)
    obs, _ = sim.reset(seed=seed, scenario_ids=ids)
    all_obs, actions, stepped = [np.asarray(obs, dtype=np.float64)], [], []
    goal_index = [sim.state.human_goal_index.copy()]

    poses = [sim.state.robot_pose()]
    for _ in range(steps):
        running = ~sim.state.done.copy()
        a = np.asarray(policy(obs), dtype=np.int64)
        obs = sim.step(a).obs
        all_obs.append(np.asarray(obs, dtype=np.float64))
        goal_index.append(sim.state.human_goal_index.copy())
        poses.append(sim.state.robot_pose())
        actions.append(a)
        stepped.append(running)
    return Recording(
        np.stack(all_obs),
        np.stack(actions),
        np.stack(stepped),
        np.stack(goal_index),
        np.stack(poses),
    )


def random_policy(seed: int) -> Policy:
    """Uniform random actions from a generator of its own."""
    rng = np.random.default_rng(seed)
    return lambda obs: rng.integers(0, NUM_ACTIONS, size=len(obs))


def epsilon_greedy(agent: Any, epsilon: float, seed: int) -> Policy:
    """A trained agent's greedy action, replaced by a uniform one with probability ``epsilon``.
    The agent's world-model state follows the actions really taken."""
    rng = np.random.default_rng(seed)
    features_of = agent.fresh_variant()
    last: list[np.ndarray] = []

    def act(obs: np.ndarray) -> np.ndarray:
        features = features_of.reset(obs) if not last else features_of.step(obs, last[0])[0]
        greedy = agent.act(features).cpu().numpy()
        explore = rng.random(len(obs)) < epsilon
        actions = np.where(explore, rng.integers(0, NUM_ACTIONS, size=len(obs)), greedy)
        last[:] = [actions]
        return actions

    return act


def model_positions(
    vae: Any, lstm: Any, recording: Recording, warmup: int, horizon: int, batch_size: int = 512
) -> tuple[np.ndarray, np.ndarray]:
    """The VAE + LSTM's positions: (N, 1 + H, 2) at ``k = 0`` (the VAE alone) and
    (N, horizon, 1 + H, 2) open loop from step ``warmup`` (see the module docstring)."""
    import torch

    vae = copy.deepcopy(vae).double().eval()
    lstm = copy.deepcopy(lstm).double().eval()
    n = recording.obs.shape[1]
    now = np.empty((n, *positions(recording.obs[0]).shape[1:]))
    ahead = np.empty((n, horizon, *now.shape[1:]))
    with torch.no_grad():
        for start in range(0, n, batch_size):
            rows = slice(start, start + batch_size)
            obs = torch.from_numpy(recording.obs[: warmup + 1, rows])  # (warmup + 1, b, D)
            actions = torch.from_numpy(recording.actions[:, rows])
            z = vae.encode(obs.reshape(-1, obs.shape[-1]))[0].reshape(*obs.shape[:2], -1)

            def decoded(latent: torch.Tensor) -> np.ndarray:
                return positions(vae.destandardize(vae.decode(latent)).numpy())

            now[rows] = decoded(z[warmup])
            state = None
            for t in range(warmup):  # teacher forcing along the real trajectory
                _, state = lstm.step(z[t], actions[t], state)
            latent = z[warmup]
            for k in range(horizon):
                latent, state = lstm.step(latent, actions[warmup + k], state)
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
    errors_of: Mapping[str, np.ndarray], valid: np.ndarray, goal_index: np.ndarray, t0: int
) -> dict[str, Any]:
    """Per k: the share of humans who drew a new goal between the velocity's first view
    (``t0 − 1``) and ``t0 + k`` (their turn cannot be foreseen: goals are not observed), and
    each predictor's humans' error (``errors_of``: (N, K, 1 + H) each) over those who kept
    their goal and over those who did not."""
    horizon = valid.shape[1]
    changed = np.stack(
        [goal_index[t0 + k] != goal_index[t0 - 1] for k in range(1, horizon + 1)], axis=1
    )  # (N, K, H)
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


def prediction_errors(
    recording: Recording,
    env_params: EnvParams,
    *,
    warmup: int,
    horizon: int,
    world_model: tuple[Any, Any] | None = None,
    planning_models: Sequence[Any] = (),
    batch_size: int = 512,
) -> dict[str, Any]:
    """k-step errors (m) of every predictor on a recording.

    Returns ``{"k": [1…horizon], "n": [episodes counted at each k], "predictors": {name:
    {"goal", "goal_ci", "humans", "humans_ci"}}}``; the model's entry (with ``world_model =
    (vae, lstm)``) also has ``"k0": {"goal", "humans"}``, the VAE's own error. With
    ``planning_models`` (one per training seed), ``"planning_model"`` holds per k the seeds'
    humans' errors and the difference from constant velocity (module docstring).
    """
    if warmup < 1:
        raise ValueError(f"warmup: must be at least 1 (a velocity needs two views), got {warmup}")
    if recording.actions.shape[0] < warmup + horizon:
        raise ValueError(
            f"the recording has {recording.actions.shape[0]} steps, "
            f"warmup + horizon needs {warmup + horizon}"
        )
    t0 = warmup
    truth = np.stack(
        [positions(recording.obs[t0 + k]) for k in range(1, horizon + 1)], axis=1
    )  # (N, K, 1 + H, 2)
    # Observation t0 + k is real when every step t0 … t0 + k − 1 was (and t0 − 1, for the
    # velocity): an episode that ended earlier is carried along frozen.
    valid = np.logical_and.accumulate(recording.stepped[t0 - 1 : t0 + horizon], axis=0)[1:].T
    future = recording.actions[t0 : t0 + horizon].T
    predicted: dict[str, np.ndarray] = {
        name: predict_positions(
            name,
            recording.obs[t0 - 1],
            recording.obs[t0],
            recording.actions[t0 - 1],
            future,
            env_params,
        )
        for name in PREDICTORS
    }
    now = None
    if world_model is not None:
        now, predicted[MODEL_PREDICTOR] = model_positions(
            *world_model, recording, warmup, horizon, batch_size
        )
    result: dict[str, Any] = {
        "k": list(range(1, horizon + 1)),
        "n": valid.sum(axis=0).tolist(),
        "predictors": {},
    }
    for name, prediction in predicted.items():
        errors = np.linalg.norm(prediction - truth, axis=-1)  # (N, K, 1 + H)
        result["predictors"][name] = _summaries(errors, valid)
    if planning_models:
        from socnav_wm.worldmodel.residual import residual_positions

        start = (recording.obs[t0 - 1], recording.obs[t0], recording.actions[t0 - 1])
        pose = None if recording.pose is None else recording.pose[t0]
        cv = np.linalg.norm(predicted["constant-velocity"] - truth, axis=-1)
        per_seed = [
            np.linalg.norm(
                residual_positions(m, *start, future, env_params, pose=pose) - truth, axis=-1
            )
            for m in planning_models
        ]  # each (N, K, 1 + H)
        result["predictors"][PLANNING_PREDICTOR] = _over_seeds(per_seed, valid)
        result["planning_model"] = _versus_constant_velocity(per_seed, cv, valid)
    if recording.goal_index is not None:
        errors_of = {n: np.linalg.norm(p - truth, axis=-1) for n, p in predicted.items()}
        if planning_models:
            errors_of[PLANNING_PREDICTOR] = np.mean(per_seed, axis=0)
        result["goal_change"] = _by_goal_change(errors_of, valid, recording.goal_index, t0)
    if now is not None:
        present = valid[:, 0]
        error_now = np.linalg.norm(now - positions(recording.obs[t0]), axis=-1)[present]
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
    planning_models: Sequence[Any] = (),
    batch_size: int = 512,
) -> dict[str, Any]:
    """The errors of every predictor (``planning_models``: the planning world model's seeds)
    under the random policy and, with ``agent``, under its ε-greedy policy:
    ``{"settings": {…}, "policies": {"random": …, "agent": …}}``, each policy's entry as
    :func:`prediction_errors` returns it. Both policies run scenarios ``0..episodes−1`` of
    ``scenario_seed`` (``params``: the ``prediction`` section)."""
    episodes, scenario_seed, epsilon = params.episodes, params.scenario_seed, params.epsilon
    warmup, horizon = params.warmup, params.horizon
    ids = np.arange(episodes)
    policies: dict[str, Policy] = {"random": random_policy(scenario_seed)}
    if agent is not None:
        policies["agent"] = epsilon_greedy(agent, epsilon, scenario_seed)
    result: dict[str, Any] = {
        "settings": {
            "episodes": episodes,
            "scenario_seed": scenario_seed,
            "warmup": warmup,
            "horizon": horizon,
            "epsilon": epsilon,
            "agent": None if agent is None else agent.variant_name,
            "planning_model_seeds": len(planning_models),
        },
        "policies": {},
    }
    for name, policy in policies.items():
        recording = record(env_params, policy, scenario_seed, ids, warmup + horizon)
        result["policies"][name] = prediction_errors(
            recording, env_params, warmup=warmup, horizon=horizon, world_model=world_model,
            planning_models=planning_models, batch_size=batch_size,
        )  # fmt: skip
    return result
