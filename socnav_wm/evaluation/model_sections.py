"""The report's sections on the models: the world model's k-step prediction errors beside the
no-learning predictors, and the planners against their ceiling (``oracle-mpc``), explained by
those errors. Parts of ``summary.md`` (:func:`~socnav_wm.evaluation.rendering.render_summary`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from socnav_wm.evaluation.comparisons import compare
from socnav_wm.evaluation.formatting import fmt_ci, fmt_p, markdown_table
from socnav_wm.evaluation.results import MethodEvaluation

__all__ = ["CEILING", "MODEL_PLANNERS", "PREDICTION_KS", "planning_section", "prediction_section"]


PREDICTION_KS = (1, 4, 8, 12, 16)
"""The steps ahead shown in the report's prediction table."""

PREDICTOR_ORDER = ("copy-last", "static", "constant-velocity", "vae-lstm", "planning-model")
POLICY_ORDER = ("random", "agent")
"""Columns and tables of the prediction section (the JSON file's keys are sorted)."""


def _ordered(names: Sequence[str], order: Sequence[str]) -> list[str]:
    return [n for n in order if n in names] + sorted(n for n in names if n not in order)


def prediction_section(prediction: Mapping[str, Any]) -> list[str]:
    """The world model's k-step errors in metres beside the no-learning predictors (the
    content of ``metrics/prediction.json``), one table per policy."""
    settings = prediction["settings"]
    lines = [
        "## The world model's predictions, in metres",
        "",
        f"Open-loop rollouts of the true actions from real states, after {settings['warmup']} "
        f"real steps, on {settings['episodes']} scenarios of seed {settings['scenario_seed']}; "
        "mean Euclidean error in the robot frame, over the episodes still running at k "
        "(`socnav-wm predict`, `metrics/prediction.json`, figure `prediction.png`). The paper "
        "never measured its world model this way. `static` and `constant-velocity` apply the "
        "robot's own motion exactly (their goal error is 0).",
        "",
    ]
    for policy in _ordered(list(prediction["policies"]), POLICY_ORDER):
        errors = prediction["policies"][policy]
        names = _ordered(list(errors["predictors"]), PREDICTOR_ORDER)
        model = "vae-lstm" if "vae-lstm" in names else None
        header = ["k", "n", *(f"{n}: humans" for n in names)]
        if model:
            header.append(f"{model}: goal")
        rows = []
        if model and "k0" in errors["predictors"][model]:
            k0 = errors["predictors"][model]["k0"]
            row = ["0 (VAE alone)", ""] + [
                f"{k0['humans']:.3f}" if n == model else "" for n in names
            ]
            rows.append([*row, f"{k0['goal']:.3f}"])
        for k in PREDICTION_KS:
            if k not in errors["k"]:
                continue
            i = errors["k"].index(k)
            row = [str(k), str(errors["n"][i])]
            row += [f"{errors['predictors'][n]['humans'][i]:.3f}" for n in names]
            if model:
                row.append(f"{errors['predictors'][model]['goal'][i]:.3f}")
            rows.append(row)
        agent = f" ({settings['agent']}, ε = {settings['epsilon']})" if policy == "agent" else ""
        lines += [f"**{policy} policy{agent}**", ""] + markdown_table(header, rows) + [""]
        if model and "constant-velocity" in names:
            ours = errors["predictors"][model]["humans"]
            cv = errors["predictors"]["constant-velocity"]["humans"]
            static = errors["predictors"]["static"]["humans"]
            below_cv = [k for k, a, b in zip(errors["k"], ours, cv, strict=True) if a < b]
            below_static = [k for k, a, b in zip(errors["k"], ours, static, strict=True) if a < b]
            lines += [
                f"- {model} predicts the humans better than constant velocity at "
                f"{_ks(below_cv)}, better than static humans at {_ks(below_static)}.",
                "",
            ]
        change = errors.get("goal_change")
        if change:
            i = errors["k"].index(max(errors["k"]))
            parts = [
                f"{name} {values['kept'][i]:.3f} m for those who kept their goal, "
                f"{values['changed'][i]:.3f} m for the others"
                for name, values in change["predictors"].items()
                if name in ("constant-velocity", "planning-model", "vae-lstm")
            ]
            lines += [
                f"- Humans draw a new goal when they reach theirs, and goals are not observed: "
                f"{change['changed_share'][i]:.0%} of the humans did within k = "
                f"{errors['k'][i]} steps. At that k: " + "; ".join(parts) + ".",
                "",
            ]
        versus = errors.get("planning_model")
        if versus:
            verdicts = dict(zip(errors["k"], versus["verdict"], strict=True))
            by = {v: [k for k, w in verdicts.items() if w == v] for v in ("better", "worse")}
            i = errors["k"].index(max(errors["k"]))
            low, high = versus["difference_ci"][i]
            lines += [
                f"- The planning model ({versus['seeds']} training seeds) against constant "
                f"velocity, humans, 95% interval over seeds: significantly better at "
                f"{_ks(by['better'])}, significantly worse at {_ks(by['worse'])}; at "
                f"k = {errors['k'][i]} the difference is {versus['difference'][i]:+.4f} m "
                f"[{low:+.4f}, {high:+.4f}].",
                "",
            ]
    return lines


CEILING = "oracle-mpc"
MODEL_PLANNERS = {
    "cv-mpc": "constant-velocity",
    "wm-mpc": "planning-model",
    "vae-lstm-mpc": "vae-lstm",
}
"""The planners that plan on a model of the observation, and the predictor of ``socnav-wm
predict`` that is their model."""


def _paired(a: MethodEvaluation, b: MethodEvaluation, metric: str) -> str:
    """``a`` − ``b`` on a rate ``metric``, paired scenario by scenario: "+x pp [low, high], p"."""
    c = compare(a.episodes, b.episodes, metric)
    return (
        f"{c.difference * 100:+.1f} pp [{c.low * 100:+.1f}, {c.high * 100:+.1f}], "
        f"p = {fmt_p(c.p_value)}"
    )


def planning_section(
    evaluations: Mapping[str, MethodEvaluation],
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]],
    prediction: Mapping[str, Any] | None,
    horizons: Mapping[str, int],
) -> list[str]:
    """The planners against ``oracle-mpc`` (same planner, the simulator as its model): how far
    each is from that ceiling, paired scenario by scenario, and the k-step errors of its model
    at its horizon (``horizons``: planner → steps; default the longest predicted) that explain
    the gap. Empty without the ceiling."""
    planners = [m for m in MODEL_PLANNERS if m in evaluations]
    if CEILING not in evaluations or not planners:
        return []
    lines = [
        "## Planning: the ceiling, and what keeps the models from it",
        "",
        f"`{CEILING}` plans with the same candidates and cost on the simulator itself (with "
        "random draws of its own): what the four actions and this planner allow on these "
        "scenarios. Each planner below plans on a model of the observation; its difference from "
        "the ceiling is paired scenario by scenario (95% interval, p of the paired test).",
        "",
    ]
    rows = []
    for method in [CEILING, *planners]:
        row = [method]
        for metric in ("success", "human_collision"):
            cell = fmt_ci(metric, summaries[method][metric])
            if method != CEILING:
                cell += "; " + _paired(evaluations[method], evaluations[CEILING], metric)
            row.append(cell)
        rows.append(row)
    header = ["planner", "success; against the ceiling", "human collisions; against the ceiling"]
    lines += markdown_table(header, rows) + [""]
    robots = [robot for robot in ("orca", "sfm") if robot in evaluations]
    if robots:
        lines += [
            "Against the ORCA and SFM robots, which read the world-frame state (planner − "
            "robot, paired scenario by scenario; 95% interval, p of the paired test):",
            "",
        ]
        rows = []
        for method in [CEILING, *planners]:
            rows.append(
                [method]
                + [
                    _paired(evaluations[method], evaluations[robot], metric)
                    for robot in robots
                    for metric in ("success", "human_collision")
                ]
            )
        header = ["planner"] + [
            f"{label} − {robot}" for robot in robots for label in ("success", "human collisions")
        ]
        lines += markdown_table(header, rows) + [""]
    collided = summaries[CEILING]["human_collision"]["mean"]
    lines.append(
        f"- `{CEILING}` itself collides with a human in {collided:.1%} of the episodes: "
        "knowing the humans' rules, though not their future random draws, the planner does "
        "not avoid those."
    )
    if prediction is None or "random" not in prediction["policies"]:
        return lines
    errors = prediction["policies"]["random"]
    longest = max(errors["k"])

    def step(planner: str) -> int | None:
        k = min(horizons.get(planner, longest), longest)
        return errors["k"].index(k) if k in errors["k"] else None

    parts = []
    for planner in planners:
        name, i = MODEL_PLANNERS[planner], step(planner)
        if i is not None and name in errors["predictors"]:
            error = errors["predictors"][name]["humans"][i]
            parts.append(f"`{planner}` ({name}) {error:.3f} m at k = {errors['k'][i]}")
    if parts:
        lines.append(
            "- The humans' mean position error of each planner's model at its horizon (random "
            "policy, as in the prediction section): " + "; ".join(parts) + "."
        )
    change = errors.get("goal_change")
    cv = change["predictors"].get("constant-velocity") if change else None
    i = step("cv-mpc")
    if cv and i is not None:
        share = change["changed_share"][i]
        overall = errors["predictors"]["constant-velocity"]["humans"][i]
        from_changes = share * cv["changed"][i] / overall if overall > 0 else math.nan
        line = (
            f"- At k = {errors['k'][i]}, {from_changes:.0%} of constant velocity's error comes "
            f"from the {share:.0%} of the humans who drew a new goal within those steps "
            f"({cv['changed'][i]:.3f} m; {cv['kept'][i]:.3f} m for those who kept theirs): "
            "goals are not in the observation, so no model of it foresees when a person turns "
            "or where to."
        )
        learned = change["predictors"].get("planning-model")
        if learned:
            line += (
                f" The planning model, which also knows where the room ends, has "
                f"{learned['changed'][i]:.3f} m for those who drew a new goal and "
                f"{learned['kept'][i]:.3f} m for the others: it trades a little on the people "
                "who walk on for more on those who turn."
            )
        lines.append(line)
    if "cv-mpc" in summaries:
        gap = summaries[CEILING]["success"]["mean"] - summaries["cv-mpc"]["success"]["mean"]
        lines.append(
            f"- The ceiling succeeds {abs(gap) * 100:.1f} points {'more' if gap >= 0 else 'less'}"
            " often than `cv-mpc` (means): with this planner on these scenarios, a better model "
            "of the humans has no more than that to win."
        )
    if "cv-mpc" in evaluations and "wm-mpc" in evaluations:
        parts = [
            f"{label} " + _paired(evaluations["wm-mpc"], evaluations["cv-mpc"], metric)
            for metric, label in (("success", "success"), ("human_collision", "human collisions"))
        ]
        lines.append(
            "- The learned model against constant velocity, the same planner otherwise "
            "(`wm-mpc` − `cv-mpc`, paired): " + "; ".join(parts) + "."
        )
    lines.append("")
    return lines


def _ks(ks: Sequence[int]) -> str:
    return "no k" if not ks else "k = " + ", ".join(map(str, ks))
