"""The report: every file written, numbers that match the per-episode Parquet, pairing and tests
on hand-made tables, Pareto by hand, claims whose verdicts follow the data, graceful absence."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from PIL import Image
from scipy import stats as scipy_stats

from socnav_wm.agents.params import AgentParams
from socnav_wm.evaluation import paper
from socnav_wm.evaluation.claims import VERDICTS, check_claims
from socnav_wm.evaluation.comparisons import clustered_mcnemar, compare, pareto_analysis
from socnav_wm.evaluation.evaluate import EvaluationResult
from socnav_wm.evaluation.formatting import fmt_ci
from socnav_wm.evaluation.intervals import mean_ci_crossed
from socnav_wm.evaluation.params import ReportParams
from socnav_wm.evaluation.records import BASELINE_SEED
from socnav_wm.evaluation.report import build_report
from socnav_wm.evaluation.results import (
    MethodEvaluation,
    load_evaluations,
    load_training_returns,
    training_summary,
)
from socnav_wm.evaluation.stats import mcnemar, wilcoxon_signed_rank
from socnav_wm.method_names import PLANNER_NAMES, VARIANT_NAMES
from socnav_wm.metrics import ALL_METRICS, PAPER_METRICS
from tests.evaluation.conftest import (
    EPISODES,
    SCENARIO_SEED,
    TEST_ENV,
    relabel,
    set_column,
    write_evaluation_files,
)

SOLVED = {
    "solved_window": AgentParams().solved_window,
    "solved_success_rate": AgentParams().solved_success_rate,
}
"""The shipped "solved" criterion (params.yaml's agent section)."""

# ------------------------------------------------------------------ fixtures


def _synthetic_dqn(orca: EvaluationResult) -> EvaluationResult:
    """``dueling-dqn`` with two seeds: ORCA's episodes, some successes and rewards changed."""
    result = relabel(orca, "dueling-dqn", (0, 1))
    table = result.episodes
    success = table["success"].to_numpy().copy()
    success[[0, 7]] = 0.0  # seed 0 fails scenario 0, seed 1 fails scenario 1
    reward = table["reward"].to_numpy() - 0.05 * np.arange(table.num_rows)
    table = set_column(set_column(table, "success", success), "reward", reward)
    return dataclasses.replace(result, episodes=table)


def _training_logs(folder: Path, variant: str, seeds: range, level: float) -> None:
    rng = np.random.default_rng(len(variant))
    for seed in seeds:
        n = 120
        returns = level * np.tanh(np.arange(n) / 30.0) + rng.normal(0, 0.1, n)
        table = pa.table(
            {
                "episode": np.arange(n, 0, -1),  # deliberately unsorted: the reader sorts
                "return": returns[::-1],
                "success": (np.arange(n) > 60)[::-1],
            }
        )
        (folder / variant).mkdir(parents=True, exist_ok=True)
        pq.write_table(table, folder / variant / f"seed-{seed}.parquet")


@pytest.fixture(scope="module")
def report(baseline_results, tmp_path_factory):
    """A report over orca, sfm (real runs) and a synthetic two-seed dueling-dqn."""
    root = tmp_path_factory.mktemp("report")
    eval_dir, metrics_dir = root / "data" / "eval", root / "metrics" / "eval"
    for result in baseline_results.values():
        write_evaluation_files(result, eval_dir, metrics_dir)
    write_evaluation_files(_synthetic_dqn(baseline_results["orca"]), eval_dir, metrics_dir)
    _training_logs(root / "data" / "training", "dueling-dqn", range(2), 0.5)
    _training_logs(root / "data" / "training", "2stepahead", range(3), 0.6)
    result = build_report(
        eval_dir,
        root / "data" / "training",
        root / "reports",
        root / "metrics" / "report.json",
        env_params=TEST_ENV,
        scenario_seed=SCENARIO_SEED,
        report=ReportParams(smoothing_window=20),
        **SOLVED,
        gif_size=96,
        gif_max_frames=10,
    )
    return root, result


# ------------------------------------------------------------------ files


def test_build_report_writes_every_file(report):
    root, result = report
    reports = root / "reports"
    assert result.summary_path == reports / "summary.md"
    assert result.pareto_path == reports / "pareto.json"
    for name in ("training_curves.png", "histograms.png", "means.png", "scenarios.gif"):
        assert (reports / "figures" / name).is_file(), name
    assert [p.name for p in result.figures] == [
        "training_curves.png",
        "histograms.png",
        "means.png",
        "scenarios.gif",
    ]
    gif = Image.open(reports / "figures" / "scenarios.gif")
    assert gif.size == (3 * 96, 96)  # three methods side by side
    assert gif.n_frames > 3

    content = json.loads((root / "metrics" / "report.json").read_text())
    assert content["methods_present"] == ["dueling-dqn", "orca", "sfm"]
    assert content["methods_absent"] == [
        "wm-dueling-dqn",
        "2stepahead",
        "maspm",
        "2stepahead-maspm",
        "cv-mpc",
        "wm-mpc",
        "vae-lstm-mpc",
        "oracle-mpc",
    ]
    assert content["scenario_seed"] == SCENARIO_SEED and content["episodes"] == EPISODES
    assert set(content["comparisons"]) == {"orca", "sfm"}
    assert set(content["comparisons"]["orca"]) == set(PAPER_METRICS)
    assert set(content["claims"]) == {c.claim_id for c in paper.CLAIMS}
    assert {c["verdict"] for c in content["claims"].values()} <= set(VERDICTS)
    claims = json.loads(result.claims_path.read_text())
    assert set(claims) == set(content["claims"])
    assert all(c["checks"] for c in claims.values())
    assert content["comparisons"]["orca"]["success"]["verdict"] in ("better", "worse", "n.s.")
    assert set(content["training"]) == {"dueling-dqn", "2stepahead"}

    pareto = json.loads((reports / "pareto.json").read_text())
    assert pareto["metrics"] == list(PAPER_METRICS)
    assert set(pareto["front"]) | set(pareto["dominated_by"]) == {"dueling-dqn", "orca", "sfm"}

    summary = result.summary_path.read_text()
    for heading in (
        "## Test metrics",
        "## Paired comparisons with `dueling-dqn`",
        "## Pareto analysis",
        "## Side by side with the paper",
        "## The paper's claims, checked",
        "## Figures",
    ):
        assert heading in summary
    absent = (
        "wm-dueling-dqn, 2stepahead, maspm, 2stepahead-maspm, cv-mpc, wm-mpc, vae-lstm-mpc, "
        "oracle-mpc"
    )
    assert f"**Not evaluated: {absent}.**" in summary
    assert "![scenarios.gif](figures/scenarios.gif)" in summary


def _table_row(summary: str, method: str) -> list[str]:
    """Cells of ``method``'s row in the first (test metrics) table of summary.md."""
    section = summary.split("## Test metrics", 1)[1]
    for line in section.splitlines():
        if line.startswith(f"| {method} |"):
            return [cell.strip() for cell in line.strip("|").split("|")]
    raise AssertionError(f"no row for {method}")


def test_summary_numbers_match_the_per_episode_parquet(report):
    root, result = report
    content = json.loads((root / "metrics" / "report.json").read_text())
    summary = result.summary_path.read_text()
    for method in ("dueling-dqn", "orca", "sfm"):
        table = pq.read_table(root / "data" / "eval" / f"{method}.parquet")
        row = _table_row(summary, method)
        assert row[1] == str(table.num_rows)
        for column, metric in enumerate(PAPER_METRICS, start=2):
            values = table[metric].to_numpy()
            direct = mean_ci_crossed(
                values, table["scenario_id"].to_numpy(), table["training_seed"].to_numpy()
            )
            entry = content["methods"][method]["metrics"][metric]
            assert entry["mean"] == pytest.approx(float(np.mean(values)), abs=1e-12)
            assert (entry["low"], entry["high"], entry["n"]) == pytest.approx(
                (direct.low, direct.high, direct.n)
            )
            expected = {"mean": direct.mean, "low": direct.low, "high": direct.high}
            assert row[column] == fmt_ci(metric, expected), (method, metric)
    # Per-seed means of the agent, by hand.
    dqn = pq.read_table(root / "data" / "eval" / "dueling-dqn.parquet")
    seeds = dqn["training_seed"].to_numpy()
    per_seed = content["methods"]["dueling-dqn"]["per_seed"]
    for seed in (0, 1):
        success = dqn["success"].to_numpy()[seeds == seed]
        assert per_seed[f"seed-{seed}"]["success"] == pytest.approx(success.mean())
    assert "per_seed" not in content["methods"]["orca"]


def test_reference_comparisons_pair_agents_with_baselines_by_scenario(report):
    root, _ = report
    content = json.loads((root / "metrics" / "report.json").read_text())
    entry = content["comparisons"]["orca"]["success"]
    # Two dueling-dqn seeds against one deterministic ORCA run, on 6 scenarios.
    assert entry["pairing"] == "scenario"
    assert (entry["num_pairs"], entry["num_scenarios"]) == (2 * EPISODES, EPISODES)
    assert entry["test"] == "clustered-mcnemar"
    # Only the two failures of dueling-dqn differ from ORCA (which it copies): +2/12.
    assert entry["difference"] == pytest.approx(2 / 12)
    assert entry["p_holm"] >= entry["p_value"]
    assert content["comparisons"]["sfm"]["reward"]["test"] == "wilcoxon"


# ------------------------------------------------------------------ absence


def test_report_with_only_baselines_says_what_is_missing(baseline_results, tmp_path):
    eval_dir = tmp_path / "eval"
    for result in baseline_results.values():
        write_evaluation_files(result, eval_dir, tmp_path / "m")
    result = build_report(
        eval_dir, tmp_path / "no-training", tmp_path / "reports", tmp_path / "report.json",
        report=ReportParams(gif_scenarios=[0]), **SOLVED, gif_size=64, gif_max_frames=5,
    )  # fmt: skip
    assert result.present == ["orca", "sfm"]
    # The paper's report looks for every method its pipeline evaluates (not wm-mpc-q: a preset's).
    assert result.absent == [*VARIANT_NAMES, *(p for p in PLANNER_NAMES if p != "wm-mpc-q")]
    summary = result.summary_path.read_text()
    assert "**Not evaluated: " + ", ".join(result.absent) + ".**" in summary
    assert "`dueling-dqn` was not evaluated: no paired comparisons." in summary
    assert "no training logs" in summary
    assert [p.name for p in result.figures] == ["histograms.png", "means.png", "scenarios.gif"]
    assert result.verdicts["best-success"] == "not testable"
    assert result.verdicts["agents-beat-baselines-success"] == "not testable"
    assert result.verdicts["training-world-models-higher"] == "not testable"
    assert json.loads((tmp_path / "report.json").read_text())["comparisons"] == {}


def test_the_report_stage_fills_the_results_blocks_of_the_readme_and_the_docs(
    baseline_results, tmp_path, monkeypatch
):
    """Run where the README and docs/evaluation.md are (as `dvc repro` does), the stage writes
    the results table into both blocks and leaves the rest of each file as it was."""
    from socnav_wm.config import Params
    from socnav_wm.stages import report as stage

    root = Path(__file__).resolve().parents[2]
    end = "<!-- /socnav-wm:results -->"
    for document in stage.RESULTS_DOCUMENTS:
        (tmp_path / document).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / document).write_text((root / document).read_text())
    for result in baseline_results.values():
        write_evaluation_files(result, tmp_path / "eval", tmp_path / "m")
    monkeypatch.chdir(tmp_path)
    params = Params.model_validate(
        {
            "env": TEST_ENV.to_dict(),
            "eval": {"scenario_seed": SCENARIO_SEED},
            "report": {"gif_scenarios": []},
        }
    )
    stage.run(
        params, eval_dir=Path("eval"), training_dir=Path("none"), out_dir=Path("reports"),
        metrics=Path("report.json"), prediction=None, tracking=False,
    )  # fmt: skip
    for document in stage.RESULTS_DOCUMENTS:
        text = (tmp_path / document).read_text()
        assert f"on the same {EPISODES} test scenarios" in text and "| `orca` |" in text, document
        assert text.split(end)[1] == (root / document).read_text().split(end)[1], document


def test_report_without_any_evaluation(tmp_path):
    stale = tmp_path / "r" / "figures" / "histograms.png"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"from an earlier run")
    result = build_report(
        tmp_path / "nothing", tmp_path / "nothing", tmp_path / "r", tmp_path / "j",
        report=ReportParams(), **SOLVED,
    )  # fmt: skip
    assert result.present == [] and result.figures == []
    assert not stale.exists()
    assert "No evaluation file was found" in result.summary_path.read_text()
    assert set(result.verdicts.values()) == {"not testable"}


def test_evaluations_on_other_scenarios_are_refused(baseline_results, tmp_path):
    write_evaluation_files(baseline_results["orca"], tmp_path, tmp_path)
    other = dataclasses.replace(baseline_results["sfm"], scenario_seed=SCENARIO_SEED + 1)
    write_evaluation_files(other, tmp_path, tmp_path)
    with pytest.raises(ValueError, match="other scenarios than orca"):
        load_evaluations(tmp_path)
    with pytest.raises(ValueError, match="another scenario_seed"):
        load_evaluations(tmp_path, ["orca"], scenario_seed=SCENARIO_SEED + 5)


# ------------------------------------------------------------------ paired tests


def _episodes(method: str, seeds, scenarios: int, **columns) -> pa.Table:
    """An episodes table: every (seed, scenario), zeros except the columns given (flat arrays)."""
    rows = len(seeds) * scenarios
    data = {
        "method": [method] * rows,
        "training_seed": np.repeat(np.asarray(seeds, dtype=np.int64), scenarios),
        "scenario_id": np.tile(np.arange(scenarios, dtype=np.int64), len(seeds)),
    }
    for metric in ALL_METRICS:
        data[metric] = np.asarray(columns.get(metric, np.zeros(rows)), dtype=np.float64)
    return pa.table(data)


def test_clustered_mcnemar_by_hand():
    # Clusters: 0 → two pairs a-only (d = +2); 1 → one b-only, one concordant (d = −1);
    # 2 → one a-only (d = +1). X² = (2 − 1 + 1)² / (4 + 1 + 1) = 4/6.
    a = np.array([1, 1, 0, 1, 1])
    b = np.array([0, 0, 1, 1, 0])
    statistic, p, b01, b10 = clustered_mcnemar(a, b, np.array([0, 0, 1, 1, 2]))
    assert statistic == pytest.approx(4 / 6)
    assert p == pytest.approx(scipy_stats.chi2.sf(4 / 6, 1))
    assert (b01, b10) == (1, 3)
    # One pair per cluster: McNemar's statistic without continuity correction, (b − c)²/(b + c).
    statistic, _, _, _ = clustered_mcnemar(a, b, np.arange(5))
    assert statistic == pytest.approx((3 - 1) ** 2 / 4)
    assert clustered_mcnemar(a, a, np.arange(5))[:2] == (0.0, 1.0)


def test_compare_pairs_by_seed_and_scenario_with_the_same_seeds():
    success_a = np.array([1, 1, 1, 0, 1, 1, 1, 1, 0, 1], dtype=float)
    success_b = np.array([0, 1, 1, 0, 0, 0, 1, 1, 0, 1], dtype=float)
    reward_a = np.arange(10, dtype=float)
    reward_b = np.array([0.5, 1, 2.5, 2, 3, 5.5, 7, 6, 8.5, 8])
    a = _episodes("a", (0, 1), 5, success=success_a, reward=reward_a)
    b = _episodes("b", (0, 1), 5, success=success_b, reward=reward_b)
    # b's rows in another order: pairs are matched by (seed, scenario), not by position.
    b = b.take(np.random.default_rng(0).permutation(b.num_rows))
    result = compare(a, b, "success")
    assert result.pairing == "seed+scenario"
    assert (result.num_pairs, result.num_scenarios) == (10, 5)
    assert result.test == "clustered-mcnemar"
    assert result.difference == pytest.approx((success_a - success_b).mean())
    expected = clustered_mcnemar(success_a, success_b, np.tile(np.arange(5), 2))
    assert result.p_value == pytest.approx(expected[1])

    result = compare(a, b, "reward")
    assert result.test == "wilcoxon"
    # Wilcoxon on the per-scenario means over the two seeds.
    per_scenario_a = reward_a.reshape(2, 5).mean(axis=0)
    per_scenario_b = reward_b.reshape(2, 5).mean(axis=0)
    expected = wilcoxon_signed_rank(per_scenario_a, per_scenario_b)
    assert (result.p_value, result.effect_size) == pytest.approx(
        (expected.p_value, expected.effect_size)
    )
    assert result.favours() == "a"  # higher reward is better, a's is higher on average


def test_compare_agent_against_baseline_and_two_baselines():
    agent = _episodes("agent", (0, 1, 2), 4, success=np.ones(12))
    baseline = _episodes("orca", (BASELINE_SEED,), 4, success=np.array([1.0, 0, 0, 1]))
    result = compare(agent, baseline, "success")
    assert result.pairing == "scenario"
    assert (result.num_pairs, result.num_scenarios) == (12, 4)
    assert result.difference == pytest.approx(0.5)
    # Two deterministic runs: one pair per scenario, the textbook McNemar.
    other = _episodes("sfm", (BASELINE_SEED,), 4, success=np.array([0.0, 0, 1, 1]))
    result = compare(baseline, other, "success")
    assert result.pairing == "seed+scenario" and result.test == "mcnemar"
    assert result.p_value == mcnemar([1, 0, 0, 1], [0, 0, 1, 1]).p_value
    # NaN values (time to goal of failures) drop their pairs.
    times = np.array([10.0, math.nan, math.nan, 12.0])
    left = _episodes("orca", (BASELINE_SEED,), 4, time_to_reach_goal=times)
    right = _episodes("sfm", (BASELINE_SEED,), 4, time_to_reach_goal=times + 1)
    assert compare(left, right, "time_to_reach_goal").num_pairs == 2


# ------------------------------------------------------------------ Pareto


def test_pareto_on_a_hand_made_table():
    base = {metric: 0.0 for metric in PAPER_METRICS}
    means = {
        # a: better than b on success, equal elsewhere → a dominates b.
        "a": {**base, "success": 0.9, "discomfort": 5.0},
        "b": {**base, "success": 0.8, "discomfort": 5.0},
        # c: worse success, less discomfort → a trade-off, non-dominated.
        "c": {**base, "success": 0.7, "discomfort": 1.0},
        # d: worse than c on discomfort and success, better than nobody.
        "d": {**base, "success": 0.6, "discomfort": 6.0},
    }
    result = pareto_analysis(means)
    assert result["front"] == ["a", "c"]
    assert result["dominated_by"] == {"b": ["a"], "d": ["a", "b", "c"]}
    assert result["directions"]["discomfort"] == "min"
    means["a"]["reward"] = math.nan
    assert pareto_analysis(means)["dropped_metrics"] == ["reward"]


# ------------------------------------------------------------------ claims


def _evaluation(table: pa.Table) -> MethodEvaluation:
    return MethodEvaluation(table["method"][0].as_py(), table, {}, None)


def _claim_inputs(maspm_success, dqn_success, maspm_reward, dqn_reward, maspm_hit, dqn_hit):
    n = 40  # scenarios; two seeds each
    evaluations = {
        "2stepahead-maspm": _episodes(
            "2stepahead-maspm", (0, 1), n, success=maspm_success, reward=maspm_reward,
            human_collision=maspm_hit,
        ),
        "dueling-dqn": _episodes(
            "dueling-dqn", (0, 1), n, success=dqn_success, reward=dqn_reward,
            human_collision=dqn_hit,
        ),
    }  # fmt: skip
    evaluations = {m: _evaluation(t) for m, t in evaluations.items()}
    means = {
        m: {k: float(np.nanmean(e.episodes[k].to_numpy())) for k in ALL_METRICS}
        for m, e in evaluations.items()
    }
    return evaluations, means


def _verdicts(evaluations, means, training=None) -> dict[str, str]:
    results = check_claims(evaluations, means, training or {})
    return {r.claim.claim_id: r.verdict for r in results}


def test_claim_verdicts_follow_the_data():
    rows = 80
    half = (np.arange(rows) % 40 < 20).astype(float)  # fails on scenarios 20..39, both seeds
    good_reward, bad_reward = np.full(rows, 0.9), np.linspace(0.0, 0.5, rows)

    # 2StepAhead-MASPM always succeeds, vanilla fails half the scenarios; no collisions.
    evaluations, means = _claim_inputs(
        np.ones(rows), half, good_reward, bad_reward, np.zeros(rows), np.zeros(rows)
    )
    verdicts = _verdicts(evaluations, means)
    # Success and reward reproduced, collisions not different: partly.
    assert verdicts["twostep-maspm-beats-dqn"] == "partly reproduced"
    assert verdicts["best-success"] == "reproduced"
    assert verdicts["world-models-beat-dqn"] == "reproduced"  # the one variant evaluated
    assert verdicts["twostep-maspm-pareto"] == "reproduced"
    assert verdicts["agents-beat-baselines-success"] == "not testable"
    assert verdicts["twostep-maspm-ranks"] == "not testable"

    # ...and vanilla also collides on the scenarios it fails: fully reproduced.
    evaluations, means = _claim_inputs(
        np.ones(rows), half, good_reward, bad_reward, np.zeros(rows), 1.0 - half
    )
    assert _verdicts(evaluations, means)["twostep-maspm-beats-dqn"] == "reproduced"

    # The other way round: the claims are contradicted.
    evaluations, means = _claim_inputs(
        half, np.ones(rows), bad_reward, good_reward, np.zeros(rows), np.zeros(rows)
    )
    verdicts = _verdicts(evaluations, means)
    assert verdicts["twostep-maspm-beats-dqn"] == "not reproduced"
    assert verdicts["best-success"] == "not reproduced"
    assert verdicts["twostep-maspm-pareto"] == "not reproduced"

    # Identical methods: nothing to decide.
    evaluations, means = _claim_inputs(
        half, half, good_reward, good_reward, np.zeros(rows), np.zeros(rows)
    )
    verdicts = _verdicts(evaluations, means)
    assert verdicts["twostep-maspm-beats-dqn"] == "inconclusive"
    assert verdicts["best-success"] == "inconclusive"

    # Evidence is spelled out with the numbers.
    results = check_claims(evaluations, means, {})
    check = results[0].checks[0]
    assert check.status == "inconclusive" and "p = " in check.evidence


def test_the_papers_claims_leave_the_planners_out():
    rows = 80
    half = (np.arange(rows) % 40 < 20).astype(float)
    evaluations, means = _claim_inputs(
        np.ones(rows), half, np.full(rows, 0.9), np.full(rows, 0.1), np.zeros(rows), np.zeros(rows)
    )
    before = _verdicts(evaluations, means)
    # A planner that beats everyone would contradict "2StepAhead-MASPM is best", were it counted.
    planner = _evaluation(
        _episodes("cv-mpc", (BASELINE_SEED,), 40, success=np.ones(40), reward=np.full(40, 2.0),
                  human_collision=np.zeros(40))
    )  # fmt: skip
    evaluations["cv-mpc"] = planner
    means["cv-mpc"] = {k: float(np.nanmean(planner.episodes[k].to_numpy())) for k in ALL_METRICS}
    assert _verdicts(evaluations, means) == before
    for result in check_claims(evaluations, means, {}):
        assert all("cv-mpc" not in (c.subject, c.other) for c in result.checks)


def _training(levels: dict[str, list[float]]) -> dict:
    """A training_summary-like dict with the given per-seed plateaus (solved never)."""
    return {
        variant: {
            "seeds": list(range(len(values))),
            "episodes": dict.fromkeys(range(len(values)), 100),
            "plateau": dict(enumerate(values)),
            "episodes_to_solve": dict.fromkeys(range(len(values))),
        }
        for variant, values in levels.items()
    }


def test_training_claims_need_enough_seeds_and_follow_the_data():
    high = [0.80, 0.82, 0.79, 0.81, 0.83]
    low = [0.50, 0.52, 0.49, 0.51, 0.53]
    others = ("dueling-dqn", "wm-dueling-dqn", "2stepahead", "maspm")
    claim = "training-twostep-maspm-highest"
    # Five seeds a side, clearly separated: reproduced (exact Mann–Whitney p = 0.008 each).
    training = _training({"2stepahead-maspm": high} | dict.fromkeys(others, low))
    assert _verdicts({}, {}, training)[claim] == "reproduced"
    # Reversed: not reproduced.
    training = _training({"2stepahead-maspm": low} | dict.fromkeys(others, high))
    assert _verdicts({}, {}, training)[claim] == "not reproduced"
    # Three seeds a side cannot reach significance (smallest p = 0.1): inconclusive.
    training = _training({"2stepahead-maspm": high[:3]} | dict.fromkeys(others, low[:3]))
    assert _verdicts({}, {}, training)[claim] == "inconclusive"
    # Missing variants are not testable.
    assert _verdicts({}, {}, _training({"dueling-dqn": low}))[claim] == "not testable"


def test_an_undecided_training_check_says_how_many_seeds_would_decide_it():
    from scipy import stats

    from socnav_wm.evaluation.claims import MAX_SEEDS_NEEDED, check_claims, seeds_needed

    rng = np.random.default_rng(0)
    others = ("dueling-dqn", "wm-dueling-dqn", "2stepahead", "maspm")
    # Three seeds a side, 2 standard deviations apart: inconclusive, and the estimate is small.
    high, low = [0.62, 0.70, 0.78], [0.54, 0.62, 0.70]
    training = _training({"2stepahead-maspm": high} | dict.fromkeys(others, low))
    (result,) = [
        r for r in check_claims({}, {}, training) if r.claim.claim_id.endswith("maspm-highest")
    ]
    assert result.verdict == "inconclusive"
    needed = {c.seeds_needed for c in result.checks}
    assert needed == {seeds_needed(high, low, 0.05 / 4)}
    assert "seeds a side would decide it (80% power)" in result.checks[0].evidence
    # The estimate is what it says: at that many seeds a side, with the same means and spread,
    # the Mann–Whitney test at α / 4 decides about 80% of simulated studies (normal seeds).
    (n,) = needed
    spread = float(np.sqrt((np.var(high, ddof=1) + np.var(low, ddof=1)) / 2))  # pooled: 0.08
    decided = np.mean([
        stats.mannwhitneyu(rng.normal(0.70, spread, n), rng.normal(0.62, spread, n)).pvalue
        <= 0.05 / 4
        for _ in range(400)
    ])  # fmt: skip
    assert 0.7 <= decided <= 0.92
    # Seeds far apart need no more than the exact test can decide: 5 a side at 0.0125
    # (smallest p 2 / 252), 4 at 0.05 (2 / 70); 3 a side can never go below p = 0.1.
    assert seeds_needed([0.9, 0.91, 0.92], [0.1, 0.11, 0.12], 0.05 / 4) == 5
    assert seeds_needed([0.9, 0.91, 0.92], [0.1, 0.11, 0.12], 0.05) == 4
    # No difference: more than the cap; fewer than 2 seeds: no estimate.
    assert seeds_needed([0.5, 0.6], [0.6, 0.5], 0.05) == MAX_SEEDS_NEEDED + 1
    assert seeds_needed([0.5], [0.6, 0.5], 0.05) is None


def test_training_summary_and_logs(tmp_path):
    folder = tmp_path / "training"
    (folder / "maspm").mkdir(parents=True)
    returns = np.array([0.0] * 10 + [1.0] * 10)
    success = np.array([False] * 10 + [True] * 10)
    pq.write_table(
        pa.table({"episode": np.arange(1, 21), "return": returns, "success": success}),
        folder / "maspm" / "seed-4.parquet",
    )
    logs = load_training_returns(folder)
    assert list(logs) == ["maspm"] and list(logs["maspm"]) == [4]
    summary = training_summary(logs, window=5, solved_window=5, solved_success_rate=0.8)
    entry = summary["maspm"]
    assert entry["seeds"] == [4] and entry["episodes"] == {4: 20}
    assert entry["plateau"][4] == pytest.approx(1.0)  # mean of the last 5 returns
    # Episodes 11.. succeed: the last 5 hold 4 successes first at episode 14.
    assert entry["episodes_to_solve"][4] == 14
    summary = training_summary(logs, window=20, solved_window=100, solved_success_rate=0.95)
    assert summary["maspm"]["plateau"][4] == pytest.approx(0.5)


def test_the_planners_are_measured_against_their_ceiling_and_explained():
    from socnav_wm.evaluation.model_sections import planning_section
    from socnav_wm.evaluation.records import summarise

    n = 40
    hits = np.zeros(n)
    hits[:2] = 1.0
    ceiling = _episodes("oracle-mpc", (BASELINE_SEED,), n, success=1 - hits, human_collision=hits)
    cv_success = np.ones(n)
    cv_success[:12] = 0.0  # 12 of 40 scenarios lost: the ceiling's 2 and 10 more
    planner = _episodes("cv-mpc", (BASELINE_SEED,), n, success=cv_success, human_collision=hits)
    evaluations = {"oracle-mpc": _evaluation(ceiling), "cv-mpc": _evaluation(planner)}
    summaries = {m: summarise(e.episodes, ALL_METRICS) for m, e in evaluations.items()}
    prediction = {
        "policies": {
            "random": {
                "k": [1, 2],
                "predictors": {"constant-velocity": {"humans": [0.01, 0.2]}},
                "goal_change": {
                    "changed_share": [0.0, 0.1],
                    "predictors": {
                        "constant-velocity": {"changed": [0.0, 1.5], "kept": [0.01, 0.05]}
                    },
                },
            }
        }
    }
    text = "\n".join(planning_section(evaluations, summaries, prediction, {"cv-mpc": 2}))
    assert "| oracle-mpc | 95.0% [" in text
    assert "| cv-mpc | 70.0% [" in text and "; -25.0 pp [" in text  # paired, scenario by scenario
    assert "`oracle-mpc` itself collides with a human in 5.0% of the episodes" in text
    assert "`cv-mpc` (constant-velocity) 0.200 m at k = 2" in text
    # 0.1 × 1.5 of the 0.2 m: three quarters of the error is the humans who drew a new goal.
    assert "At k = 2, 75% of constant velocity's error comes from the 10% of the humans" in text
    assert "The ceiling succeeds 25.0 points more often than `cv-mpc`" in text
    assert "wm-mpc` − `cv-mpc`" not in text  # no learned model evaluated
    # With wm-mpc: its paired difference from cv-mpc, and its model's split by goal change.
    learned = np.ones(n)
    learned[:2] = 0.0  # loses only the ceiling's 2: 10 scenarios more than cv-mpc wins
    wm = _episodes("wm-mpc", (BASELINE_SEED,), n, success=learned, human_collision=hits)
    evaluations["wm-mpc"] = _evaluation(wm)
    summaries["wm-mpc"] = summarise(wm, ALL_METRICS)
    split = prediction["policies"]["random"]["goal_change"]["predictors"]
    split["planning-model"] = {"changed": [0.0, 1.2], "kept": [0.01, 0.06]}
    text = "\n".join(planning_section(evaluations, summaries, prediction, {"cv-mpc": 2}))
    assert "(`wm-mpc` − `cv-mpc`, paired): success +25.0 pp [" in text
    assert "Against the ORCA and SFM robots" not in text  # neither evaluated
    orca = _episodes("orca", (BASELINE_SEED,), n, success=cv_success, human_collision=hits)
    evaluations["orca"] = _evaluation(orca)
    text = "\n".join(planning_section(evaluations, summaries, prediction, {"cv-mpc": 2}))
    assert "| planner | success − orca | human collisions − orca |" in text
    assert "| wm-mpc | +25.0 pp [" in text and "| cv-mpc | +0.0 pp [" in text
    assert "has 1.200 m for those who drew a new goal and 0.060 m for the others" in text
    assert planning_section({"cv-mpc": evaluations["cv-mpc"]}, summaries, prediction, {}) == []
