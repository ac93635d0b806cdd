"""k-step prediction errors in metres (socnav_wm/worldmodel/prediction.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.ego import PREDICTORS
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.params import PredictionParams
from socnav_wm.worldmodel.prediction import (
    MODEL_PREDICTOR,
    prediction_errors,
    random_policy,
    record,
)
from socnav_wm.worldmodel.vae import VAE

ENV = EnvParams()


def _errors(recording, warmup: int, horizon: int, batch_size: int = 512, **models):
    """prediction_errors with one rollout per episode from ``warmup``."""
    params = PredictionParams(warmup=warmup, horizon=horizon)
    return prediction_errors(recording, ENV, params, batch_size=batch_size, **models)


@pytest.fixture(scope="module")
def recording():
    return record(ENV, random_policy(0), seed=11, scenario_ids=np.arange(24), steps=9)


@pytest.fixture(scope="module")
def world_model():
    torch.manual_seed(0)
    return VAE(23, 32, 4), LatentLSTM(4, 4, 16)


def test_errors_do_not_depend_on_the_batch_size(recording, world_model) -> None:
    one = _errors(recording, 3, 6, world_model=world_model,
                            batch_size=1)  # fmt: skip
    many = _errors(recording, 3, 6, world_model=world_model,
                             batch_size=512)  # fmt: skip
    for name in (*PREDICTORS, MODEL_PREDICTOR):
        for key in ("goal", "humans"):
            np.testing.assert_allclose(
                one["predictors"][name][key], many["predictors"][name][key], rtol=0, atol=1e-12
            )


def test_goal_is_exact_with_ego_motion_and_counts_only_running_episodes(recording) -> None:
    errors = _errors(recording, 3, 6)
    assert errors["k"] == [1, 2, 3, 4, 5, 6]
    assert errors["n"] == sorted(errors["n"], reverse=True) and errors["n"][0] <= 24
    for name in ("static", "constant-velocity"):
        assert max(errors["predictors"][name]["goal"]) < 1e-5
    # copy-last ignores the robot's motion: it is wrong as soon as the robot moves.
    assert errors["predictors"]["copy-last"]["goal"][-1] > 0.1
    cv, static = (errors["predictors"][n]["humans"] for n in ("constant-velocity", "static"))
    assert all(c < s for c, s in zip(cv, static, strict=True))
    low, high = errors["predictors"]["static"]["humans_ci"][0]
    assert low <= static[0] <= high


def test_bad_windows_are_refused(recording) -> None:
    with pytest.raises(ValueError, match="warmup"):
        _errors(recording, 0, 3)
    with pytest.raises(ValueError, match="warmup \\+ starts × horizon"):
        _errors(recording, 5, 8)


def test_evaluate_prediction_reports_each_policy_and_draws_them(tmp_path, world_model) -> None:
    from socnav_wm.evaluation.figures import prediction_figure
    from socnav_wm.evaluation.model_sections import prediction_section
    from socnav_wm.worldmodel.prediction import evaluate_prediction

    settings = PredictionParams(episodes=5, scenario_seed=3, warmup=2, horizon=3, epsilon=0.1)
    result = evaluate_prediction(ENV, settings, world_model=world_model, agent=None)
    assert list(result["policies"]) == ["random"]
    assert result["settings"]["horizon"] == 3
    errors = result["policies"]["random"]["predictors"]
    assert set(errors) == {*PREDICTORS, MODEL_PREDICTOR}
    assert set(errors[MODEL_PREDICTOR]["k0"]) == {"goal", "humans"}
    prediction_figure(result, tmp_path / "prediction.png")
    assert (tmp_path / "prediction.png").stat().st_size > 1000
    section = "\n".join(prediction_section(result))
    assert "| 0 (VAE alone) |" in section and "vae-lstm: goal" in section
    assert "vae-lstm predicts the humans better than constant velocity at" in section
    with pytest.raises(ValueError, match="epsilon"):
        PredictionParams(episodes=5, scenario_seed=3, warmup=2, horizon=3, epsilon=1.5)


def _planning_models(count: int, perturbed: bool, max_speed: float | None = None):
    from socnav_wm.worldmodel.residual import ResidualDynamics

    models = []
    for seed in range(count):
        torch.manual_seed(seed)
        model = ResidualDynamics(ENV.num_humans, 8, ENV.dt, max_speed)
        if perturbed:  # the untrained model is constant velocity; this one is not
            torch.nn.init.normal_(model.net[-1].weight, std=0.5)
        models.append(model)
    return models


def test_the_untrained_planning_model_is_constant_velocity_on_every_seed(recording) -> None:
    from socnav_wm.worldmodel.prediction import PLANNING_PREDICTOR

    errors = _errors(recording, 3, 6, planning_models=_planning_models(3, False))
    np.testing.assert_allclose(
        errors["predictors"][PLANNING_PREDICTOR]["humans"],
        errors["predictors"]["constant-velocity"]["humans"],
        atol=1e-9,
    )
    versus = errors["planning_model"]
    assert versus["seeds"] == 3 and versus["verdict"] == ["no different"] * 6
    assert max(abs(d) for d in versus["difference"]) < 1e-9
    # With the speed cap it differs by rounding only, the same on every seed: still no different.
    capped = _planning_models(3, False, ENV.human_max_speed)
    versus = _errors(recording, 3, 6, planning_models=capped)["planning_model"]
    assert max(abs(d) for d in versus["difference"]) < 1e-4
    assert versus["verdict"] == ["no different"] * 6


def test_a_perturbed_planning_model_is_measured_worse_and_batch_size_does_not_matter(
    recording,
) -> None:
    from socnav_wm.worldmodel.prediction import PLANNING_PREDICTOR

    models = _planning_models(3, True)
    one = _errors(recording, 3, 6, planning_models=models,
                            batch_size=1)  # fmt: skip
    many = _errors(recording, 3, 6, planning_models=models)
    for key in ("goal", "humans"):
        np.testing.assert_allclose(
            one["predictors"][PLANNING_PREDICTOR][key],
            many["predictors"][PLANNING_PREDICTOR][key],
            rtol=0, atol=1e-12,
        )  # fmt: skip
    versus = many["planning_model"]
    assert versus["verdict"][-1] == "worse" and versus["difference"][-1] > 0
    low, high = versus["difference_ci"][-1]
    assert low <= versus["difference"][-1] <= high
    # The goal is kinematics: exact for the learned model too.
    assert max(many["predictors"][PLANNING_PREDICTOR]["goal"]) < 1e-5
    from socnav_wm.evaluation.model_sections import prediction_section

    section = "\n".join(
        prediction_section(
            {"settings": {"warmup": 3, "episodes": 24, "scenario_seed": 11, "agent": None,
                          "epsilon": 0.0}, "policies": {"random": many}}
        )
    )  # fmt: skip
    assert "| planning-model: humans |" in section.replace("k | n |", "")
    assert "significantly worse at k = " in section


def test_errors_are_split_by_whether_a_human_drew_a_new_goal() -> None:
    rec = record(ENV, random_policy(1), seed=5, scenario_ids=np.arange(40), steps=21)
    errors = _errors(rec, 5, 16)
    change = errors["goal_change"]
    shares = change["changed_share"]
    assert all(0.0 <= s <= 1.0 for s in shares) and shares[-1] >= shares[0]
    assert shares[-1] > 0  # at 16 steps some human reaches its goal
    cv = change["predictors"]["constant-velocity"]
    # A human who kept its goal walks nearly straight: constant velocity is far better there.
    assert cv["kept"][-1] < cv["changed"][-1]
    # The split is exhaustive: the share-weighted parts give the overall mean (same rows).
    k = len(shares) - 1
    overall = errors["predictors"]["constant-velocity"]["humans"][k]
    mixed = shares[k] * cv["changed"][k] + (1 - shares[k]) * cv["kept"][k]
    assert abs(overall - mixed) < 1e-9


def test_later_starts_add_rollouts_and_the_first_start_is_unchanged(recording) -> None:
    one = _errors(recording, 3, 3)
    params = PredictionParams(warmup=3, horizon=3, starts=2)
    two = prediction_errors(recording, ENV, params, batch_size=512)
    assert all(b > a for a, b in zip(one["n"], two["n"], strict=True))
    with pytest.raises(ValueError, match="starts × horizon needs 12"):
        prediction_errors(recording, ENV, PredictionParams(warmup=3, horizon=3, starts=3),
                          batch_size=512)  # fmt: skip


SCENE = EnvParams(
    num_humans=6, humans_see_robot=True, tables=(1, 2), plants=(1, 1), groups=(1, 1),
    group_size=(2, 2),
)  # fmt: skip


@pytest.fixture(scope="module")
def scene_recording():
    return record(SCENE, random_policy(2), seed=7, scenario_ids=np.arange(40), steps=21)


def _split(rec, distance: float, **models):
    params = PredictionParams(warmup=5, horizon=8, starts=2, interaction_distance=distance)
    return prediction_errors(rec, SCENE, params, batch_size=512, **models)


def test_the_errors_are_split_by_what_each_human_met(scene_recording) -> None:
    split = _split(scene_recording, 1.5)["interactions"]
    share = split["share"]
    assert set(share) == {"robot", "humans", "group", "obstacle", "goal change", "none"}
    # Two of six humans walk in the group, whatever the window.
    np.testing.assert_allclose(share["group"], 2 / 6)
    for name in ("robot", "humans", "obstacle", "goal change"):
        assert 0 < share[name][-1] < 1, name
    # "none" is the rest: at most the share of those who met nothing else.
    assert all(n <= 1 - g for n, g in zip(share["none"], share["group"], strict=True))
    cv = split["predictors"]["constant-velocity"]
    assert cv["none"][-1] < cv["goal change"][-1]  # a new goal is what velocity cannot know
    # Far enough, everyone meets everything; near zero, nothing.
    far = _split(scene_recording, 100.0)["interactions"]["share"]
    assert far["robot"] == far["humans"] == far["obstacle"] == [1.0] * 8
    assert far["none"] == [0.0] * 8
    near = _split(scene_recording, 1e-6)["interactions"]["share"]
    assert near["robot"] == near["humans"] == near["obstacle"] == [0.0] * 8


def test_a_human_who_does_not_see_the_robot_never_meets_it() -> None:
    blind = SCENE.model_copy(update={"humans_see_robot": False})
    rec = record(blind, random_policy(2), seed=7, scenario_ids=np.arange(10), steps=21)
    params = PredictionParams(warmup=5, horizon=8, starts=2, interaction_distance=100.0)
    share = prediction_errors(rec, blind, params, batch_size=512)["interactions"]["share"]
    assert share["robot"] == [0.0] * 8 and share["humans"] == [1.0] * 8


def test_the_split_pairs_the_planning_model_with_constant_velocity(scene_recording) -> None:
    from socnav_wm.worldmodel.residual import ResidualDynamics

    models = []
    for perturbed in (False, True):
        torch.manual_seed(0)
        model = ResidualDynamics(SCENE.num_humans, 8, SCENE.dt, None)
        if perturbed:
            torch.nn.init.normal_(model.net[-1].weight, std=0.5)
        models.append(model)
    same = _split(scene_recording, 1.5, planning_models=models[:1])["interactions"]
    worse = _split(scene_recording, 1.5, planning_models=models[1:])["interactions"]
    for name, rows in same["planning_model"].items():
        assert max(abs(d) for d in rows["difference"] if d == d) < 1e-9, name
    rows = worse["planning_model"]["humans"]
    assert rows["rollouts"][-1] > 0 and rows["difference_ci"][-1][0] > 0  # clearly worse
    means = worse["predictors"]
    assert means["planning-model"]["humans"][-1] > means["constant-velocity"]["humans"][-1]


def test_evaluate_prediction_measures_under_a_planner_too() -> None:
    from socnav_wm.methods import method
    from socnav_wm.planning.params import PlanningParams
    from socnav_wm.worldmodel.prediction import evaluate_prediction

    planner = method("cv-mpc").configured(ENV, {"planning": PlanningParams()})
    settings = PredictionParams(episodes=4, scenario_seed=3, warmup=2, horizon=3, epsilon=0.0)
    result = evaluate_prediction(
        ENV, settings, world_model=None, agent=None, planner=("cv-mpc", planner)
    )
    assert list(result["policies"]) == ["random", "cv-mpc"]
    assert result["settings"]["planner"] == "cv-mpc"
    under = result["policies"]["cv-mpc"]
    assert under["n"][0] == 4 and "interactions" in under
