"""Where the pipeline keeps its files: every default path, written once.

The command line's options, the stages and the planners read their default paths from
:data:`LAYOUT`; dvc.yaml names the same files. Paths are relative to the working directory (the
repository root). This module imports nothing of the project (it is the lowest layer).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


def agent_file(agents_dir: Path, variant: str, seed: int) -> Path:
    """Agent ``variant``'s file for training seed ``seed`` in the agents folder ``agents_dir``."""
    return agents_dir / variant / f"seed-{seed}.pt"


def planning_model_file(planning_dir: Path, seed: int) -> Path:
    """The planning world model of training seed ``seed`` in the folder ``planning_dir``."""
    return planning_dir / f"seed-{seed}.pt"


@dataclass(frozen=True)
class Layout:
    """The pipeline's files and folders, relative to the working directory."""

    params: Path = Path("params.yaml")
    """The parameters file."""

    # data
    rollouts: Path = Path("data/rollouts")
    """Random-policy rollouts, Parquet shards (stage ``collect``)."""
    training_logs: Path = Path("data/training")
    """Agents' training logs: ``{variant}/seed-{seed}.parquet``."""
    eval_dir: Path = Path("data/eval")
    """Evaluation episodes: ``{method}.parquet`` and ``{method}-trajectories.parquet``."""
    scenario_episodes: Path = Path("data/scenarios")
    """Each scenario preset's evaluation episodes: ``{preset}/{method}.parquet``."""
    study_runs: Path = Path("data/studies")
    """Every study run's files and checkpoints: ``{study}/...``."""

    # models
    vae: Path = Path("models/vae.pt")
    lstm: Path = Path("models/lstm.pt")
    agents_dir: Path = Path("models/agents")
    """Trained agents: ``{variant}/seed-{seed}.pt``."""
    planning_dir: Path = Path("models/planning")
    """Planning world models: ``seed-{seed}.pt``."""
    checkpoints: Path = Path("checkpoints")
    """Resumable training checkpoints."""

    # metrics
    collect_metrics: Path = Path("metrics/collect.json")
    vae_metrics: Path = Path("metrics/vae.json")
    vae_history: Path = Path("metrics/vae_history.json")
    lstm_metrics: Path = Path("metrics/lstm.json")
    lstm_history: Path = Path("metrics/lstm_history.json")
    agent_metrics_dir: Path = Path("metrics/agents")
    """Agents' summary metrics: ``{variant}/seed-{seed}.json``."""
    planning_metrics_dir: Path = Path("metrics/planning")
    """Planning world models' metrics: ``seed-{seed}.json``."""
    eval_metrics_dir: Path = Path("metrics/eval")
    """Evaluation metrics: ``{method}.json``."""
    scenario_metrics: Path = Path("metrics/scenarios")
    """Each scenario preset's evaluation metrics: ``{preset}/{method}.json``; ``summary.json``."""
    report_metrics: Path = Path("metrics/report.json")
    prediction_metrics: Path = Path("metrics/prediction.json")

    # reports and documents
    reports: Path = Path("reports")
    report_claims: Path = Path("reports/claims.json")
    prediction_figure: Path = Path("reports/prediction.png")
    scenario_presets: Path = Path("configs/scenarios")
    """The scenario presets: one overlay ``{preset}.yaml`` each (docs/scenarios.md)."""
    scenarios_report: Path = Path("reports/scenarios.md")
    """The per-preset table of the non-learning methods (stage ``scenarios_report``)."""
    scenarios_documents: tuple[Path, ...] = (Path("docs/scenarios.md"),)
    """The markdown files whose ``scenarios`` block the scenarios report fills."""
    study_reports: Path = Path("reports/studies")
    """Each study's report: ``{study}/claims.json``, ``results.parquet``, ``summary.md``."""
    results_documents: tuple[Path, ...] = (Path("README.md"), Path("docs/evaluation.md"))
    """The markdown files whose ``results`` block the report fills."""
    studies_documents: tuple[Path, ...] = (Path("docs/studies.md"),)
    """The markdown files whose ``claims`` block the study claims fill."""
    episode_gif: Path = Path("episode.gif")
    """What ``socnav-wm render`` writes."""

    def agent(self, variant: str, seed: int = 0) -> Path:
        """Agent ``variant``'s file for training seed ``seed``."""
        return agent_file(self.agents_dir, variant, seed)

    @property
    def prediction_agent(self) -> Path:
        """The agent whose ε-greedy policy ``socnav-wm predict`` measures under: dueling-dqn's,
        seed 0."""
        return self.agent("dueling-dqn", 0)

    def planning_model(self, seed: int = 0) -> Path:
        """The planning world model of training seed ``seed`` (``wm-mpc`` plans with seed 0's)."""
        return planning_model_file(self.planning_dir, seed)

    def study_run_dir(self, study: str) -> Path:
        """Study ``study``'s runs."""
        return self.study_runs / study

    def study_report_dir(self, study: str) -> Path:
        """Study ``study``'s report."""
        return self.study_reports / study


LAYOUT = Layout()
"""The pipeline's layout."""
