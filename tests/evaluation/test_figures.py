"""Figures: the rolling mean by hand, every figure writes a readable image, GIF frames line up."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.figures import (
    histograms_figure,
    means_figure,
    training_curves_figure,
)
from socnav_wm.evaluation.results import smooth
from socnav_wm.evaluation.scenes import scenario_frames, scenarios_gif
from socnav_wm.metrics import PAPER_METRICS


def test_smooth_is_a_trailing_mean_by_hand():
    values = [1.0, 3.0, 5.0, 7.0, 9.0]
    # Window 2: 1, (1+3)/2, (3+5)/2, (5+7)/2, (7+9)/2.
    np.testing.assert_allclose(smooth(values, 2), [1.0, 2.0, 4.0, 6.0, 8.0])
    # Window 3: expanding at the start, then over 3.
    np.testing.assert_allclose(smooth(values, 3), [1.0, 2.0, 3.0, 5.0, 7.0])
    # Window 1 is the identity; a window longer than the data is the expanding mean.
    np.testing.assert_allclose(smooth(values, 1), values)
    np.testing.assert_allclose(smooth(values, 100), [1.0, 2.0, 3.0, 4.0, 5.0])
    assert smooth([], 5).size == 0
    with pytest.raises(ValueError, match="window"):
        smooth(values, 0)


def _image(path) -> Image.Image:
    image = Image.open(path)
    image.load()
    return image


def test_training_curves_figure(tmp_path):
    rng = np.random.default_rng(0)
    returns = {
        "dueling-dqn": {0: rng.normal(0, 1, 300), 1: rng.normal(0, 1, 280)},
        "2stepahead": {0: rng.normal(0.5, 1, 300)},  # one seed: no band
    }
    path = tmp_path / "figures" / "training_curves.png"
    training_curves_figure(returns, path, window=20, paper_plateaus={"dueling-dqn": 0.52})
    image = _image(path)
    assert image.format == "PNG" and image.width > 300
    assert [p.name for p in path.parent.iterdir()] == ["training_curves.png"]  # no temp files


def test_histograms_and_means_figures(tmp_path):
    rng = np.random.default_rng(1)
    values = {}
    for method, size in (("orca", 20), ("dueling-dqn", 40)):
        values[method] = {metric: rng.random(size) for metric in PAPER_METRICS}
        values[method]["success"] = (rng.random(size) < 0.8).astype(float)
    values["orca"]["reward"][0] = math.nan  # left out
    values["orca"]["discomfort"][:] = 3.0  # one value: a one-bin histogram
    path = tmp_path / "histograms.png"
    histograms_figure(values, PAPER_METRICS, path)
    assert _image(path).format == "PNG"

    summaries = {
        method: {
            metric: {"mean": float(np.nanmean(v)), "low": math.nan, "high": math.nan}
            for metric, v in metrics.items()
        }
        for method, metrics in values.items()
    }
    summaries["orca"]["reward"] = {"mean": 0.5, "low": 0.4, "high": 0.6}
    path = tmp_path / "means.png"
    means_figure(summaries, PAPER_METRICS, path)
    assert _image(path).format == "PNG"


def _straight_episode(scenario_id: int, steps: int, success: bool) -> Episode:
    t = np.arange(steps + 1, dtype=np.float64)
    robot = np.stack([-3.0 + 0.1 * t, np.zeros_like(t)], axis=1)
    humans = np.tile(np.array([[2.0, 2.0], [-2.0, -2.0], [3.0, -3.0]]), (steps + 1, 1, 1))
    return Episode(
        scenario_id=scenario_id,
        robot_xy=robot,
        robot_theta=np.zeros(steps + 1),
        goal_xy=np.array([4.0, 0.0]),
        human_xy=humans,
        human_theta=np.zeros((steps + 1, 3)),
        actions=np.ones(steps, dtype=np.int64),
        rewards=np.zeros(steps),
        dmin=np.full(steps, 2.0),
        success=success,
        collision=None,
        truncated=not success,
    )


def test_scenario_frames_tile_the_methods_and_hold_the_end():
    params = EnvParams()
    episodes = {"a": _straight_episode(0, 10, True), "b": _straight_episode(0, 4, False)}
    frames = scenario_frames(episodes, params, size=64, columns=4, max_frames=100, hold=3)
    # t = 0..10 (11 frames) plus 3 copies of the last.
    assert len(frames) == 11 + 3
    assert frames[0].shape == (64, 128, 3) and frames[0].dtype == np.uint8
    # Method b ended at t = 4: its cell no longer changes after that.
    np.testing.assert_array_equal(frames[5][:, 64:], frames[10][:, 64:])
    assert not np.array_equal(frames[5][:, :64], frames[10][:, :64])
    # Long episodes are subsampled, the last step always kept.
    frames = scenario_frames(episodes, params, size=64, max_frames=4, hold=0)
    assert len(frames) == 5  # t = 0, 3, 6, 9 and 10
    # A grid: three methods in two columns make two rows.
    three = {**episodes, "c": _straight_episode(0, 2, True)}
    assert scenario_frames(three, params, size=64, columns=2, hold=0)[0].shape == (128, 128, 3)


def test_scenarios_gif_plays_each_scenario_in_turn(tmp_path):
    params = EnvParams()
    scenarios = [
        {"a": _straight_episode(s, 5 + s, True), "b": _straight_episode(s, 3, False)}
        for s in range(3)
    ]
    path = tmp_path / "scenarios.gif"
    scenarios_gif(scenarios, params, path, size=64, columns=2, max_frames=100)
    image = _image(path)
    assert image.format == "GIF" and image.size == (128, 64)
    # (6 + 7 + 8) distinct frames; the held copies fold into the last one of each scenario.
    assert image.n_frames == 6 + 7 + 8
    with pytest.raises(ValueError, match="no scenario"):
        scenarios_gif([], params, tmp_path / "empty.gif")
