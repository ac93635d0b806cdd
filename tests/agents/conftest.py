"""Fixtures for the agent tests: tiny random-initialised world models saved as real files."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
import torch

from socnav_wm.worldmodel.files import save_lstm, save_vae
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE

# The native update (test_native.py) compiles into a cache folder: the tests' own, not the user's.
if not os.environ.get("SOCNAV_WM_CACHE_DIR"):
    os.environ["SOCNAV_WM_CACHE_DIR"] = tempfile.mkdtemp(prefix="socnav-wm-tests-")
    atexit.register(shutil.rmtree, os.environ["SOCNAV_WM_CACHE_DIR"], ignore_errors=True)

OBS_DIM = 23
LATENT = 6
HIDDEN = 10


def tiny_world_model(seed: int = 0) -> tuple[VAE, LatentLSTM]:
    """A small VAE (23 → 6) and LSTM (hidden 10), random weights, eval mode."""
    torch.manual_seed(seed)
    vae = VAE(input_dim=OBS_DIM, hidden_dim=16, latent_dim=LATENT).eval()
    lstm = LatentLSTM(latent_dim=LATENT, num_actions=4, hidden_dim=HIDDEN).eval()
    return vae, lstm


@pytest.fixture(scope="session")
def world_model_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(vae.pt, lstm.pt) written with the world model's own save functions."""
    folder = tmp_path_factory.mktemp("world_model")
    vae, lstm = tiny_world_model()
    save_vae(folder / "vae.pt", vae)
    save_lstm(folder / "lstm.pt", lstm)
    return folder / "vae.pt", folder / "lstm.pt"


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Small networks gain nothing from threads, and on a shared 2-core machine OpenMP threads
    waiting on each other make the training tests many times slower."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
