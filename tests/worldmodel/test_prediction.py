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


@pytest.fixture(scope="module")
def recording():
    return record(ENV, random_policy(0), seed=11, scenario_ids=np.arange(24), steps=9)


@pytest.fixture(scope="module")
def world_model():
    torch.manual_seed(0)
    return VAE(23, 32, 4), LatentLSTM(4, 4, 16)


def test_errors_do_not_depend_on_the_batch_size(recording, world_model) -> None:
    one = prediction_errors(recording, ENV, warmup=3, horizon=6, world_model=world_model,
                            batch_size=1)  # fmt: skip
    many = prediction_errors(recording, ENV, warmup=3, horizon=6, world_model=world_model,
                             batch_size=512)  # fmt: skip
    for name in (*PREDICTORS, MODEL_PREDICTOR):
        for key in ("goal", "humans"):
            np.testing.assert_allclose(
                one["predictors"][name][key], many["predictors"][name][key], rtol=0, atol=1e-12
            )


def test_goal_is_exact_with_ego_motion_and_counts_only_running_episodes(recording) -> None:
    errors = prediction_errors(recording, ENV, warmup=3, horizon=6)
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
        prediction_errors(recording, ENV, warmup=0, horizon=3)
    with pytest.raises(ValueError, match="warmup \\+ horizon"):
        prediction_errors(recording, ENV, warmup=5, horizon=8)


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

    errors = prediction_errors(
        recording, ENV, warmup=3, horizon=6, planning_models=_planning_models(3, False)
    )
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
    versus = prediction_errors(recording, ENV, warmup=3, horizon=6, planning_models=capped)[
        "planning_model"
    ]
    assert max(abs(d) for d in versus["difference"]) < 1e-4
    assert versus["verdict"] == ["no different"] * 6


def test_a_perturbed_planning_model_is_measured_worse_and_batch_size_does_not_matter(
    recording,
) -> None:
    from socnav_wm.worldmodel.prediction import PLANNING_PREDICTOR

    models = _planning_models(3, True)
    one = prediction_errors(recording, ENV, warmup=3, horizon=6, planning_models=models,
                            batch_size=1)  # fmt: skip
    many = prediction_errors(recording, ENV, warmup=3, horizon=6, planning_models=models)
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
    errors = prediction_errors(rec, ENV, warmup=5, horizon=16)
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
