"""The VAE: loss formula by hand, built-in standardisation, training, determinism, files."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from matplotlib.figure import Figure

from socnav_wm.data.shards import RolloutError
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel import evaluation, training
from socnav_wm.worldmodel.evaluation import encode_observations
from socnav_wm.worldmodel.figures import plot_reconstruction
from socnav_wm.worldmodel.files import ModelFileError, load_lstm, load_vae, save_lstm, save_vae
from socnav_wm.worldmodel.fit import fit_vae
from socnav_wm.worldmodel.fitting import NonFiniteTrainingError
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.params import VaeParams
from socnav_wm.worldmodel.training import train_vae
from socnav_wm.worldmodel.vae import VAE, kl_divergence, vae_loss
from tests.data.test_shards import make_episodes, write_dataset

RADIUS_COLUMN = 6  # human 0's radius: constant in real observations


def synthetic_observations(n: int, seed: int) -> np.ndarray:
    """23-d observations from a 3-d latent through a fixed random linear map, plus noise."""
    mixing = np.random.default_rng(1234).standard_normal((3, 23)) * np.linspace(0.2, 3.0, 23)
    rng = np.random.default_rng(seed)
    obs = rng.standard_normal((n, 3)) @ mixing + 0.05 * rng.standard_normal((n, 23)) + 1.0
    obs[:, RADIUS_COLUMN] = 0.36
    return obs.astype(np.float32)


def cpu_params(**changes) -> VaeParams:
    """A small VAE on the CPU with the plain ELBO (β = 1); ``changes`` override."""
    settings = {"latent_dim": 4, "hidden_dim": 32, "kl_weight": 1.0, "learning_rate": 1e-3,
                "batch_size": 128, "max_epochs": 3, "patience": 5, "device": "cpu"}  # fmt: skip
    return VaeParams(**{**settings, **changes})


def small_training(seed: int = 0, max_epochs: int = 30):
    return train_vae(
        synthetic_observations(2000, seed=1),
        synthetic_observations(400, seed=2),
        cpu_params(hidden_dim=64, learning_rate=3e-3, max_epochs=max_epochs),
        seed=seed,
    )


def test_kl_matches_a_hand_computed_value() -> None:
    # mu = (1, 0), variance = (1, 2): KL = ½ Σ (σ² + μ² − 1 − ln σ²) = ½ (1 + 1 − 1 − 0)
    # + ½ (2 + 0 − 1 − ln 2) = 1 − ½ ln 2.
    mu = torch.tensor([[1.0, 0.0]])
    logvar = torch.tensor([[0.0, math.log(2.0)]])
    assert kl_divergence(mu, logvar).item() == pytest.approx(1.0 - 0.5 * math.log(2.0))
    assert kl_divergence(torch.zeros(3, 5), torch.zeros(3, 5)).tolist() == [0.0, 0.0, 0.0]


def test_vae_loss_sums_features_and_averages_the_batch() -> None:
    recon = torch.tensor([[1.0, 2.0], [0.0, 0.0]])
    target = torch.zeros(2, 2)
    mu = torch.tensor([[1.0, 0.0], [0.0, 0.0]])
    logvar = torch.tensor([[0.0, math.log(2.0)], [0.0, 0.0]])
    total, recon_mse, kl = vae_loss(recon, target, mu, logvar, kl_weight=0.5)
    expected_kl = (1.0 - 0.5 * math.log(2.0)) / 2  # second sample has KL 0
    assert recon_mse.item() == pytest.approx(5.0 / 4)  # (1 + 4 + 0 + 0) / 4 elements
    assert kl.item() == pytest.approx(expected_kl)
    assert total.item() == pytest.approx(5.0 / 2 + 0.5 * expected_kl)  # sum-SE per sample


def test_standardisation_is_built_in_and_constant_features_stay_finite() -> None:
    obs = synthetic_observations(500, seed=0)
    vae = VAE()
    vae.fit_normalization(obs)
    assert vae.obs_std[RADIUS_COLUMN].item() > 0
    standardized = vae.standardize(torch.from_numpy(obs))
    assert torch.all(standardized[:, RADIUS_COLUMN] == 0)
    assert torch.allclose(standardized.mean(0), torch.zeros(23), atol=1e-4)
    mu, logvar = vae.encode(torch.from_numpy(obs))
    assert mu.shape == logvar.shape == (500, 16)
    assert torch.isfinite(mu).all()
    assert torch.allclose(vae.destandardize(standardized), torch.from_numpy(obs), atol=1e-5)


def test_vae_beats_the_mean_predictor_by_a_wide_margin() -> None:
    result = small_training()
    metrics = result.metrics
    assert metrics["recon_to_baseline_ratio"] < 0.1
    assert metrics["val_recon_mse_raw"] < 0.1 * metrics["baseline_mse_raw"]
    assert 1 <= metrics["best_epoch"] <= metrics["epochs_run"]
    assert {"train_loss", "val_loss", "val_recon_mse", "val_kl"} <= set(result.history[0])
    # The restored model is the best epoch's.
    best_val = min(row["val_loss"] for row in result.history)
    assert metrics["val_loss"] == pytest.approx(best_val, rel=1e-5)


def test_same_seed_gives_identical_weights_and_other_seed_differs() -> None:
    first = small_training(seed=7, max_epochs=2).model.state_dict()
    second = small_training(seed=7, max_epochs=2).model.state_dict()
    other = small_training(seed=8, max_epochs=2).model.state_dict()
    assert all(torch.equal(first[key], second[key]) for key in first)
    assert not torch.equal(first["mu_head.weight"], other["mu_head.weight"])


def test_on_epoch_callback_sees_every_epoch() -> None:
    seen: list[int] = []
    train_vae(
        synthetic_observations(200, 1),
        synthetic_observations(50, 2),
        cpu_params(latent_dim=2, hidden_dim=16, batch_size=64, patience=10),
        seed=0,
        on_epoch=lambda epoch, metrics: seen.append(epoch),
    )
    assert seen == [1, 2, 3]


def test_save_load_round_trip(tmp_path: Path) -> None:
    vae = VAE(23, 32, 4)
    vae.fit_normalization(synthetic_observations(100, 0))
    path = tmp_path / "models" / "vae.pt"
    save_vae(path, vae, extra={"val_recon_mse": np.float32(0.5), "episodes": [1, 2]})
    loaded = load_vae(path, "cpu")
    assert not loaded.training
    obs = synthetic_observations(10, 3)
    np.testing.assert_array_equal(encode_observations(loaded, obs), encode_observations(vae, obs))
    assert [p.name for p in path.parent.iterdir()] == ["vae.pt"]  # no temporary left


def test_bad_model_files_give_one_line_errors_naming_the_file(tmp_path: Path) -> None:
    vae_path, lstm_path = tmp_path / "vae.pt", tmp_path / "lstm.pt"
    save_vae(vae_path, VAE(23, 16, 2))
    save_lstm(lstm_path, LatentLSTM(2, 4, 8))
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a model at all")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(vae_path.read_bytes()[:200])
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    cases = [
        (lambda: load_vae(tmp_path / "missing.pt"), tmp_path / "missing.pt", "no such"),
        (lambda: load_vae(garbage), garbage, "not a readable model file"),
        (lambda: load_vae(truncated), truncated, "not a readable model file"),
        (lambda: load_vae(foreign), foreign, "not a socnav-wm model file"),
        (lambda: load_lstm(vae_path), vae_path, "holds a 'vae' model, expected a 'lstm'"),
        (lambda: load_vae(lstm_path), lstm_path, "holds a 'lstm' model, expected a 'vae'"),
    ]
    for load, path, problem in cases:
        with pytest.raises(ModelFileError) as error:
            load()
        message = str(error.value)
        assert "\n" not in message and str(path) in message and problem in message, message


def test_reconstruction_figure(tmp_path: Path) -> None:
    vae = VAE(23, 16, 2)
    vae.fit_normalization(synthetic_observations(100, 0))
    figure = plot_reconstruction(vae, synthetic_observations(6, 1))
    assert isinstance(figure, Figure)
    assert len(figure.axes) == 4
    figure.savefig(tmp_path / "reconstruction.png")
    assert (tmp_path / "reconstruction.png").stat().st_size > 0


def _one_line_non_finite(error: pytest.ExceptionInfo[NonFiniteTrainingError]) -> str:
    message = str(error.value)
    assert "\n" not in message
    assert "no model was written" in message
    return message


def test_exploding_learning_rate_stops_the_training_with_one_line() -> None:
    epochs: list[int] = []
    with pytest.raises(NonFiniteTrainingError) as error:
        train_vae(
            synthetic_observations(500, seed=1),
            synthetic_observations(100, seed=2),
            cpu_params(learning_rate=1e30, max_epochs=5),
            seed=0,
            on_epoch=lambda epoch, _: epochs.append(epoch),
        )
    message = _one_line_non_finite(error)
    pattern = r"VAE training stopped: training loss became (nan|inf) at epoch 1 \(batch \d+\)"
    assert re.match(pattern, message)
    assert epochs == []  # the failing epoch is never reported as a result


def test_loss_turning_nan_names_epoch_and_batch(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = {"n": 0}

    def nan_on_the_seventh_call(*args, **kwargs):
        total, recon, kl = vae_loss(*args, **kwargs)
        calls["n"] += 1
        # 500 rows / 128 = 4 batches, then 1 validation pass, per epoch: epoch 2, batch 2.
        if calls["n"] == 7:
            total = total * math.nan
        return total, recon, kl

    for module in (training, evaluation):  # the training batches and the validation
        monkeypatch.setattr(module, "vae_loss", nan_on_the_seventh_call)
    with pytest.raises(NonFiniteTrainingError) as error:
        _tiny_vae_training()
    assert _one_line_non_finite(error) == (
        "VAE training stopped: training loss became nan at epoch 2 (batch 2); no model was written"
    )


def test_weights_turning_nan_stop_the_training(monkeypatch: pytest.MonkeyPatch) -> None:
    step = torch.optim.Adam.step
    calls = {"n": 0}

    def poisoning_step(self, *args, **kwargs):
        result = step(self, *args, **kwargs)
        calls["n"] += 1
        if calls["n"] == 8:  # the last batch of epoch 2
            with torch.no_grad():
                self.param_groups[0]["params"][0].view(-1)[0] = math.nan
        return result

    monkeypatch.setattr(torch.optim.Adam, "step", poisoning_step)
    with pytest.raises(NonFiniteTrainingError, match="non-finite at epoch 2;") as error:
        _tiny_vae_training()
    _one_line_non_finite(error)


def _tiny_vae_training():
    return train_vae(
        synthetic_observations(500, seed=1),
        synthetic_observations(100, seed=2),
        cpu_params(),
        seed=0,
    )


def test_fit_vae_refuses_a_shard_with_a_nan_observation(tmp_path: Path) -> None:
    episodes = make_episodes(0, [30, 30, 30, 30])
    episodes["obs"][64, 5] = np.nan
    paths = write_dataset(tmp_path, [episodes], max_rows=60)
    with pytest.raises(RolloutError) as error:
        fit_vae(tmp_path, EnvParams(), VaeParams(max_epochs=1, hidden_dim=16, latent_dim=4), seed=0)
    assert str(error.value) == f"{paths[1]}: row 4, column obs[5]: not finite (nan)"
