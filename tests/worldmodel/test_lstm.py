"""The latent LSTM: step form == sequence form, all-actions step, training, evaluation, files."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch
from matplotlib.figure import Figure

from socnav_wm.data.shards import RolloutError
from socnav_wm.data.windows import Windows, make_windows, split_episodes
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.evaluation import evaluate_lstm
from socnav_wm.worldmodel.figures import plot_latent_predictions
from socnav_wm.worldmodel.files import load_lstm, save_lstm, save_vae
from socnav_wm.worldmodel.fit import fit_lstm
from socnav_wm.worldmodel.fitting import NonFiniteTrainingError
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.params import LstmParams
from socnav_wm.worldmodel.training import train_lstm
from socnav_wm.worldmodel.vae import VAE
from tests.data.test_shards import make_episodes, write_dataset

LATENT = 4
# Action-dependent drift of the synthetic latent dynamics: z_{t+1} = z_t + DRIFT[a_t].
DRIFT = np.random.default_rng(99).standard_normal((4, LATENT)).astype(np.float32) * 0.3
DRIFT[0] = 0.0  # "stop" keeps the latent where it is


def synthetic_episodes(num_episodes: int, length: int, seed: int) -> tuple[np.ndarray, ...]:
    """(latents, actions, episode_ids, next_latents) rows of random-action episodes."""
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, 4, (num_episodes, length))
    z = np.zeros((num_episodes, length + 1, LATENT), dtype=np.float32)
    z[:, 0] = 0.5 * rng.standard_normal((num_episodes, LATENT))
    z[:, 1:] = z[:, :1] + np.cumsum(DRIFT[actions], axis=1)
    episode_ids = np.repeat(np.arange(num_episodes), length)
    return (
        z[:, :-1].reshape(-1, LATENT),
        actions.reshape(-1),
        episode_ids,
        z[:, 1:].reshape(-1, LATENT),
    )


def synthetic_windows(seed: int = 0) -> tuple[Windows, Windows]:
    latents, actions, episode_ids, next_latents = synthetic_episodes(300, 8, seed)
    train, val = split_episodes(episode_ids, val_fraction=0.2, seed=seed)
    return (
        make_windows(latents[train], actions[train], episode_ids[train], next_latents[train], 8),
        make_windows(latents[val], actions[val], episode_ids[val], next_latents[val], 8),
    )


def train_small(train: Windows, val: Windows, seed: int = 0, max_epochs: int = 40):
    return train_lstm(
        train,
        val,
        LstmParams(
            hidden_dim=64,
            learning_rate=1e-2,
            batch_size=32,
            max_epochs=max_epochs,
            patience=8,
            device="cpu",
        ),
        seed=seed,
    )


def random_state(batch: int, hidden: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return (
        torch.randn(batch, hidden, generator=generator).tanh(),
        torch.randn(batch, hidden, generator=generator),
    )


def test_step_form_equals_sequence_form() -> None:
    torch.manual_seed(0)
    model = LatentLSTM(latent_dim=16, num_actions=4, hidden_dim=256)
    z = torch.randn(6, 9, 16)
    actions = torch.randint(0, 4, (6, 9))
    for initial in (None, random_state(6, 256, seed=1)):
        with torch.no_grad():
            sequence, (h_seq, c_seq) = model(z, actions, initial)
            state = initial
            steps = []
            for t in range(z.shape[1]):
                prediction, state = model.step(z[:, t], actions[:, t], state)
                steps.append(prediction)
        torch.testing.assert_close(torch.stack(steps, dim=1), sequence, atol=1e-5, rtol=0)
        torch.testing.assert_close(state[0], h_seq, atol=1e-5, rtol=0)
        torch.testing.assert_close(state[1], c_seq, atol=1e-5, rtol=0)
    assert sequence.shape == (6, 9, 16) and h_seq.shape == c_seq.shape == (6, 256)


def test_step_all_actions_slot_k_equals_step_with_action_k() -> None:
    torch.manual_seed(0)
    model = LatentLSTM()
    z = torch.randn(5, 16)
    for state in (None, random_state(5, 256, seed=2), model.initial_state(5)):
        with torch.no_grad():
            predictions, (h_all, c_all) = model.step_all_actions(z, state)
            assert predictions.shape == (5, 4, 16) and h_all.shape == c_all.shape == (5, 4, 256)
            for action in range(4):
                chosen = torch.full((5,), action, dtype=torch.int64)
                prediction, (h, c) = model.step(z, chosen, state)
                torch.testing.assert_close(predictions[:, action], prediction, atol=1e-6, rtol=0)
                torch.testing.assert_close(h_all[:, action], h, atol=1e-6, rtol=0)
                torch.testing.assert_close(c_all[:, action], c, atol=1e-6, rtol=0)


def test_initial_state_is_zeros() -> None:
    h, c = LatentLSTM(hidden_dim=32).initial_state(3, "cpu")
    assert h.shape == c.shape == (3, 32)
    assert not h.any() and not c.any()


def test_lstm_learns_action_dependent_dynamics_far_better_than_copy_last() -> None:
    train, val = synthetic_windows()
    result = train_small(train, val)
    metrics = evaluate_lstm(result.model, val)
    assert metrics["one_step_mse"] < 0.1 * metrics["copy_last_one_step_mse"]
    assert metrics["two_step_mse"] < 0.2 * metrics["copy_last_two_step_mse"]
    assert metrics["one_step_ratio"] < 0.1
    assert metrics["one_step_mse"] == pytest.approx(result.metrics["val_loss"], rel=1e-4)
    assert [row["epoch"] for row in result.history] == list(range(1, len(result.history) + 1))


def test_copy_last_errors_match_a_hand_computation() -> None:
    latents, actions, episode_ids, next_latents = synthetic_episodes(20, 8, seed=3)
    windows = make_windows(latents, actions, episode_ids, next_latents, seq_len=4)
    metrics = evaluate_lstm(LatentLSTM(LATENT, 4, 8), windows)
    per_action = (DRIFT**2).mean(axis=1)  # copy-last error of one step with action a
    assert metrics["copy_last_one_step_mse"] == pytest.approx(per_action[actions].mean(), rel=1e-5)
    # Two-step pairs: t and t+1 in the same 4-step window, with a_{t+1} == a_t; then
    # z_{t+2} − z_t = 2·DRIFT[a_t].
    grid = actions.reshape(20, 2, 4)
    repeated = grid[..., :-1] == grid[..., 1:]
    expected = (4 * per_action[grid[..., :-1][repeated]]).mean()
    assert metrics["two_step_count"] == repeated.sum()
    assert metrics["copy_last_two_step_mse"] == pytest.approx(expected, rel=1e-5)
    assert metrics["one_step_count"] == len(actions)


def test_same_seed_gives_identical_weights() -> None:
    train, val = synthetic_windows()
    first = train_small(train, val, seed=3, max_epochs=2).model.state_dict()
    second = train_small(train, val, seed=3, max_epochs=2).model.state_dict()
    assert all(torch.equal(first[key], second[key]) for key in first)


def test_save_load_round_trip_and_figure(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model = LatentLSTM(LATENT, 4, 16)
    path = tmp_path / "lstm.pt"
    save_lstm(path, model, extra={"seq_len": 8})
    loaded = load_lstm(path, torch.device("cpu"))
    z = torch.randn(3, 5, LATENT)
    actions = torch.randint(0, 4, (3, 5))
    with torch.no_grad():
        torch.testing.assert_close(loaded(z, actions)[0], model(z, actions)[0], atol=0, rtol=0)
    latents, episode_actions, _, next_latents = synthetic_episodes(1, 12, seed=0)
    figure = plot_latent_predictions(loaded, latents, episode_actions, next_latents, dims=(0, 1))
    assert isinstance(figure, Figure) and len(figure.axes) == 2
    figure.savefig(tmp_path / "latents.png")
    assert (tmp_path / "latents.png").stat().st_size > 0


def test_exploding_learning_rate_stops_the_training_with_one_line() -> None:
    train, val = synthetic_windows()
    epochs: list[int] = []
    with pytest.raises(NonFiniteTrainingError) as error:
        train_lstm(
            train,
            val,
            LstmParams(
                hidden_dim=16,
                learning_rate=1e30,
                batch_size=32,
                max_epochs=5,
                patience=5,
                device="cpu",
            ),
            seed=0,
            on_epoch=lambda epoch, _: epochs.append(epoch),
        )
    message = str(error.value)
    assert "\n" not in message
    assert re.fullmatch(
        r"LSTM training stopped: training loss became (nan|inf) at epoch 1 \(batch \d+\); "
        r"no model was written",
        message,
    )
    assert epochs == []


def test_non_finite_validation_loss_stops_the_training() -> None:
    train, val = synthetic_windows()
    val.targets[0, 0, 0] = float("inf")
    with pytest.raises(NonFiniteTrainingError) as error:
        train_small(train, val, max_epochs=3)
    assert str(error.value) == (
        "LSTM training stopped: validation loss became inf at epoch 1; no model was written"
    )


def test_fit_lstm_refuses_a_shard_with_a_nan_next_observation(tmp_path: Path) -> None:
    episodes = make_episodes(0, [30, 30])
    episodes["next_obs"][12, 3] = np.nan
    (path,) = write_dataset(tmp_path / "rollouts", [episodes], max_rows=100)
    vae = tmp_path / "vae.pt"
    save_vae(vae, VAE(23, 16, LATENT))
    with pytest.raises(RolloutError) as error:
        fit_lstm(
            tmp_path / "rollouts", vae, EnvParams(), LstmParams(max_epochs=1, hidden_dim=16), seed=0
        )
    assert str(error.value) == f"{path}: row 12, column next_obs[3]: not finite (nan)"
