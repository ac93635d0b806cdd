"""Fixtures for the evaluation tests: the two baselines evaluated once per session on a few short
test scenarios, and helpers to build agent files and synthetic evaluations without training."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.evaluate import EvaluationResult, evaluate_method, write_evaluation

# Short episodes (80 steps) so that some time out: every outcome path gets exercised.
TEST_ENV = EnvParams(max_steps=80)
SCENARIO_SEED = 11
EPISODES = 6


@pytest.fixture(scope="session")
def baseline_results() -> dict[str, EvaluationResult]:
    """ORCA and SFM evaluated on scenarios 0..5 of SCENARIO_SEED (real simulator, real code)."""
    return {
        method: evaluate_method(
            method, env_params=TEST_ENV, scenario_seed=SCENARIO_SEED, episodes=EPISODES
        )
        for method in ("orca", "sfm")
    }


def write_evaluation_files(
    result: EvaluationResult, eval_dir: Path, metrics_dir: Path
) -> tuple[Path, Path, Path]:
    """Write ``result`` where the pipeline puts it: ``{eval_dir}/{method}.parquet``,
    ``{eval_dir}/{method}-trajectories.parquet`` and ``{metrics_dir}/{method}.json``.

    Returns:
        The three paths, in that order.
    """
    episodes = eval_dir / f"{result.method}.parquet"
    trajectories = eval_dir / f"{result.method}-trajectories.parquet"
    metrics = metrics_dir / f"{result.method}.json"
    write_evaluation(result, episodes, trajectories, metrics)
    return episodes, trajectories, metrics


def relabel(result: EvaluationResult, method: str, seeds: tuple[int, ...]) -> EvaluationResult:
    """A synthetic evaluation of ``method``: ``result``'s episodes copied once per seed.

    Used to stand in for a trained agent in report tests; the caller changes metric columns to
    taste with :func:`set_column`.
    """

    def copies(table: pa.Table) -> pa.Table:
        parts = []
        for seed in seeds:
            part = table.set_column(
                table.column_names.index("method"), "method", pa.array([method] * table.num_rows)
            )
            part = part.set_column(
                part.column_names.index("training_seed"),
                "training_seed",
                pa.array(np.full(table.num_rows, seed, dtype=np.int64)),
            )
            parts.append(part)
        return pa.concat_tables(parts)

    return EvaluationResult(
        method=method,
        scenario_seed=result.scenario_seed,
        num_scenarios=result.num_scenarios,
        env_params=result.env_params,
        training_seeds=seeds,
        episodes=copies(result.episodes),
        trajectories=copies(result.trajectories),
        wall_time=0.0,
        settings={"synthetic": True},
    )


def set_column(table: pa.Table, name: str, values: np.ndarray) -> pa.Table:
    """``table`` with column ``name`` replaced by float64 ``values``."""
    return table.set_column(
        table.column_names.index(name), name, pa.array(np.asarray(values, dtype=np.float64))
    )


def save_tiny_agent(path: Path, variant: str, env_params: EnvParams, seed: int) -> Path:
    """A random-initialised agent of ``variant`` written with the agents' own ``save_agent``.

    Tiny networks (and a tiny world model for the world-model variants), nothing trained.
    """
    import torch

    from socnav_wm.agents.agent_file import env_params_obs_dim, save_agent
    from socnav_wm.agents.dueling import DuelingQNetwork
    from socnav_wm.agents.features import VARIANTS, make_variant
    from socnav_wm.agents.params import AgentParams
    from socnav_wm.agents.training import TrainResult
    from tests.agents.conftest import tiny_world_model

    vae = lstm = None
    if VARIANTS[variant].needs_world_model:
        vae, lstm = tiny_world_model(seed)
    params = AgentParams(trunk_sizes=(16,), stream_size=8)
    features = make_variant(variant, vae, lstm, params, obs_dim=env_params_obs_dim(env_params))
    torch.manual_seed(seed)
    q_network = DuelingQNetwork(features.feature_dim, 4, (16,), 8).eval()
    result = TrainResult(
        q_network=q_network,
        variant=variant,
        params=params,
        env_params=env_params,
        seed=seed,
        episodes=[],
        episodes_to_solve=None,
        env_steps=0,
        updates=0,
        wall_time=0.0,
        vae=vae,
        lstm=lstm,
    )
    save_agent(path, result)
    return path
