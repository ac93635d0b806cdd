"""The README's results table (socnav-wm report writes it into the results blocks): units in
its header, and the verdict lines under it, computed from the numbers."""

from __future__ import annotations

from socnav_wm.evaluation import paper


def test_the_results_table_has_units_and_its_verdicts_follow_the_numbers():
    """The README's table: units in the header; under it, the claims' verdicts and, computed
    from the intervals, where a robot or a planner beats every learned agent."""
    from socnav_wm.evaluation.claims import ClaimResult
    from socnav_wm.evaluation.rendering import RESULTS_METRICS, results_table

    def entry(mean: float, half: float = 0.01) -> dict[str, float]:
        return {"mean": mean, "low": mean - half, "high": mean + half}

    base = {m: entry(0.5) for m in RESULTS_METRICS}
    summaries = {
        "dueling-dqn": {**base, "success": entry(0.80), "human_collision": entry(0.15)},
        "maspm": {**base, "success": entry(0.85), "human_collision": entry(0.12)},
        # Better than both agents on success; on collisions only within an interval of one.
        "orca": {**base, "success": entry(0.95), "human_collision": entry(0.11, 0.02)},
        "cv-mpc": {**base, "success": entry(0.84, 0.05)},
    }
    claims = [
        ClaimResult(paper.CLAIMS[0], "not reproduced"),
        ClaimResult(paper.CLAIMS[5], "reproduced"),
        ClaimResult(paper.CLAIMS[7], "inconclusive"),
    ]
    table = results_table(
        summaries, list(summaries), num_scenarios=10, scenario_seed=3, claims=claims
    ).splitlines()
    header = next(line for line in table if line.startswith("| method"))
    assert "success (%) ↑" in header and "human_collision (%) ↓" in header
    assert "discomfort (steps) ↓" in header and "simulation_time (s) ↓" in header
    assert "distance_travelled (m) ↓" in header
    claims_line, robots_line = table[-2:]
    assert claims_line.startswith("**The paper's claims: 1 of 3 reproduced**")
    assert "reproduced: twostep-maspm-pareto" in claims_line
    assert "not reproduced: best-success" in claims_line
    assert "inconclusive: training-twostep-maspm-highest" in claims_line
    assert "`orca` on success;" in robots_line and "`cv-mpc` on none." in robots_line
    # Without claims or without agents, no verdict line is made up.
    only_robots = {m: summaries[m] for m in ("orca", "cv-mpc")}
    table = results_table(only_robots, list(only_robots), num_scenarios=10, scenario_seed=3)
    assert table.splitlines()[-1].startswith("| `cv-mpc` |")
