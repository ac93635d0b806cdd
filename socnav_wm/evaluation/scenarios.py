"""The room a world model has, per scenario preset: every non-learning method's test metrics in
each preset, ``oracle-mpc`` − ``cv-mpc`` paired, and the field's published numbers side by side.

Reads what the ``scenarios`` pipeline (``scenarios/dvc.yaml``) writes: for preset ``P`` and
method ``M``, ``metrics/scenarios/P/M.json`` (the format of ``metrics/eval/M.json``) and the
episodes ``data/scenarios/P/M.parquet`` (for the paired comparison, scenario by scenario); where
a preset has a planning model of its own, its prediction errors split by what the humans met
(``metrics/scenarios/P/prediction.json``, ``socnav-wm predict``'s output).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from socnav_wm.evaluation.comparisons import compare
from socnav_wm.io import read_json

__all__ = [
    "PUBLISHED",
    "OTHER_PLANNERS",
    "SCENARIO_METHODS",
    "TABLE_METRICS",
    "Published",
    "ScenarioTable",
    "scenario_table",
]

SCENARIO_METHODS: tuple[str, ...] = ("orca", "sfm", "cv-mpc", "oracle-mpc")
"""The non-learning methods evaluated in every preset, in the table's order."""

OTHER_PLANNERS: dict[str, str] = {
    "wm-mpc": "wm-mpc",
    "oracle-mpc (blind)": "blind/oracle-mpc",
    "wm-mpc-q": "wm-mpc-q",
    "cv-mpc-q": "cv-q/wm-mpc-q",
}
"""Planners evaluated in some presets only, after the others in the table and compared with
``cv-mpc`` and ``oracle-mpc`` where they were: name → their files' path under the preset's
folders without the suffix. ``wm-mpc`` plans on a model learned in the preset; ``oracle-mpc
(blind)`` is ``oracle-mpc`` whose clones' humans do not react to the robot
(``planning.oracle_reactions`` false): what knowing that reaction is worth; ``wm-mpc-q`` is
``wm-mpc`` with a critic trained in the preset (its value at the horizon, its actions);
``cv-mpc-q`` is ``wm-mpc-q`` on constant velocity (an untrained planning model) with the same
critic: what the critic alone adds to ``cv-mpc``, and what the learned model adds to it
(:attr:`ScenarioTable.model_gain`)."""

TABLE_METRICS: tuple[tuple[str, str], ...] = (
    ("success", "success"),
    ("human_collision", "human coll."),
    ("obstacle_collision", "obstacle coll."),
    ("wall_collision", "wall coll."),
    ("max_steps", "timeout"),
    ("time_to_reach_goal", "time to goal (s)"),
)
"""(metric, column title) of the per-preset table; rates in %, the time in seconds."""

DQN_METRICS: tuple[str, ...] = ("success", "human_collision", "max_steps")
"""The test metrics of the preset's agents that the report shows (rates)."""

MODEL_SEED_DIR = "model-seed-"
"""Under a preset's folders, ``model-seed-<S>/wm-mpc-q.*``: ``wm-mpc-q`` on the preset's planning
model of training seed ``S`` (the pipeline's ``wm-mpc-q`` plans on seed 0), with the same critic:
does the learned model's share hold for another training of it?"""

TRANSFER_DIR = "transfer"
"""Under a tested-in preset's folders, ``transfer/<trained-in preset>/wm-mpc.*``: ``wm-mpc`` on
the model of another preset (``evaluate --transfer``)."""

SPLIT_KS: tuple[int, ...] = (1, 4, 16)
"""The steps ahead at which the report gives the planning model's error split by interaction."""

GAP_POINTS = 3.0
"""``oracle-mpc`` − ``cv-mpc`` success, in points, that makes a preset one where a world model
has room to matter (with its 95% interval above 0)."""


@dataclass(frozen=True)
class Published:
    """A published row of the field's benchmark, for one preset and method."""

    preset: str
    method: str
    success: float
    collision: float
    time: float
    source: str


PUBLISHED: tuple[Published, ...] = (
    Published(
        "crowdnav",
        "orca",
        0.43,
        0.57,
        10.86,
        "CrowdNav (Chen et al., ICRA 2019, Table I, invisible robot; vita-epfl/CrowdNav "
        "`test.py --policy orca`, 500 cases)",
    ),
    Published(
        "crowdnav-20",
        "orca",
        0.69,
        0.29,
        14.77,
        "CrowdNav++ (Shuijing725/CrowdNav_Prediction_AttnGraph, "
        "trained_models/ORCA_no_rand/test/test_00000.pt.log)",
    ),
    Published(
        "crowdnav-20",
        "sfm",
        0.34,
        0.64,
        19.95,
        "CrowdNav++ (trained_models/SF_no_rand/test/test_00000.pt.log)",
    ),
)
"""The numbers the presets ``crowdnav`` and ``crowdnav-20`` are compared with (success rate,
collision rate, mean time to goal of the successes in seconds)."""


@dataclass(frozen=True)
class ScenarioTable:
    """What :func:`scenario_table` found."""

    summaries: dict[str, dict[str, dict[str, dict[str, float]]]]
    """preset → method → metric → {mean, low, high, n}."""
    gaps: dict[str, dict[str, Any]]
    """preset → the paired ``oracle-mpc`` − ``cv-mpc`` success difference (points)."""
    missing: list[str]
    """``preset/method`` pairs without a metrics file."""
    learned: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    """preset → planner of :data:`OTHER_PLANNERS` → its paired success difference (points)
    from ``cv-mpc`` (``versus_physics``) and from ``oracle-mpc`` (``versus_oracle``)."""
    transfer: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    """tested-in preset → trained-in preset → ``wm-mpc`` on the model of the other preset
    (``--transfer``): its ``success`` summary and its paired success difference (points) from
    ``cv-mpc`` (``versus_physics``) and from ``wm-mpc`` on the preset's own model
    (``versus_native``, where that was evaluated)."""
    dqn: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    """preset → agent variant → its seeds' test metrics (``seeds``, and per metric of
    :data:`DQN_METRICS` the mean and 95% t-interval over seeds) from the preset's study
    (``{preset}/dqn/results.parquet``, ``socnav-wm sweep``'s output)."""
    model_gain: dict[str, dict[str, Any]] = field(default_factory=dict)
    """preset → the paired success difference (points) of ``wm-mpc-q`` from ``cv-mpc-q``: the
    learned model's worth with the same critic, where both were evaluated."""
    model_seeds: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    """preset → training seed of its planning model (``"0"``: the pipeline's ``wm-mpc-q``) →
    ``wm-mpc-q``'s ``success`` summary on that model and its paired success difference (points)
    from ``cv-mpc-q`` (``versus_control``) and from ``cv-mpc`` (``versus_physics``), where
    ``wm-mpc-q`` was evaluated on more than one seed (:data:`MODEL_SEED_DIR`)."""
    split: dict[str, dict[str, Any]] = field(default_factory=dict)
    """preset → the planning model's humans' error split by interaction under the policy it
    plans with (``policy``, ``distance``, ``k`` and per interaction ``share``, constant
    velocity's ``error`` and the model's paired ``difference`` with intervals, at
    :data:`SPLIT_KS`)."""

    def markdown(self) -> str:
        """The per-preset table, the gaps and the published comparisons, as markdown."""
        lines = [
            "| preset | method | " + " | ".join(title for _, title in TABLE_METRICS) + " |",
            "|---|---|" + "---|" * len(TABLE_METRICS),
        ]
        for preset, methods in self.summaries.items():
            for method, metrics in methods.items():
                cells = [_cell(metric, metrics.get(metric)) for metric, _ in TABLE_METRICS]
                lines.append(f"| `{preset}` | `{method}` | " + " | ".join(cells) + " |")
        lines += [
            "",
            "Rates in % of the test scenarios with their 95% intervals; time to goal: mean "
            "over the successful episodes (s).",
            "",
            "| preset | `oracle-mpc` − `cv-mpc` success (points, paired) | p (McNemar) | "
            f"room for a world model (≥ {GAP_POINTS:g} points, interval above 0) |",
            "|---|---|---|---|",
        ]
        for preset, gap in self.gaps.items():
            verdict = "yes" if gap["room"] else "no"
            lines.append(f"| `{preset}` | {_interval(gap)} | {_p(gap['p_value'])} | {verdict} |")
        if self.learned:
            lines += [
                "",
                "| preset | planner | − `cv-mpc` (points, paired) | p | − `oracle-mpc` (points, "
                "paired) | p |",
                "|---|---|---|---|---|---|",
            ]
            for preset, planners in self.learned.items():
                for name, versus in planners.items():
                    a, b = versus["versus_physics"], versus["versus_oracle"]
                    lines.append(
                        f"| `{preset}` | `{name}` | {_interval(a)} | {_p(a['p_value'])} | "
                        f"{_interval(b)} | {_p(b['p_value'])} |"
                    )
        if self.model_gain:
            lines += [
                "",
                "| preset | `wm-mpc-q` − `cv-mpc-q`: the learned model, the same critic "
                "(points, paired) | p |",
                "|---|---|---|",
            ]
            for preset, gain in self.model_gain.items():
                lines.append(f"| `{preset}` | {_interval(gain)} | {_p(gain['p_value'])} |")
        if self.model_seeds:
            lines += ["", *self.model_seed_rows()]
        if self.dqn:
            lines += ["", *self.dqn_rows()]
        if self.transfer:
            lines += ["", *self.transfer_rows()]
        if self.split:
            lines += ["", *self.split_rows()]
        published = self.published_rows()
        if published:
            lines += [
                "",
                "| preset | method | published success / collision / time | here: success "
                "[95%] / collision / time | published success in the interval |",
                "|---|---|---|---|---|",
                *published,
            ]
        return "\n".join(lines) + "\n"

    def model_seed_rows(self) -> list[str]:
        """``wm-mpc-q`` on each training seed of the preset's planning model, the same critic."""
        lines = [
            "| preset | planning model seed | `wm-mpc-q` success | − `cv-mpc-q`: the learned "
            "model (points, paired) | p | − `cv-mpc` (points, paired) | p |",
            "|---|---|---|---|---|---|---|",
        ]
        for preset, seeds in self.model_seeds.items():
            for seed, row in seeds.items():
                a, b = row["versus_control"], row["versus_physics"]
                control = "– | –" if a is None else f"{_interval(a)} | {_p(a['p_value'])}"
                lines.append(
                    f"| `{preset}` | {seed} | {_cell('success', row['success'])} | {control} | "
                    f"{_interval(b)} | {_p(b['p_value'])} |"
                )
        return lines

    def dqn_rows(self) -> list[str]:
        """The paper's five agents trained in a preset, as a markdown table."""
        rows = [
            "The paper's question in a preset: its five Dueling DQN variants (the VAE + LSTM "
            "retrained on the preset's rollouts), trained and tested in the preset; rates in % "
            "with their 95% intervals over the training seeds:",
            "",
            "| preset | variant | seeds | success | human coll. | timeout |",
            "|---|---|---|---|---|---|",
        ]
        for preset, variants in self.dqn.items():
            for variant, result in variants.items():
                cells = [_cell(metric, result[metric]) for metric in DQN_METRICS]
                rows.append(
                    f"| `{preset}` | `{variant}` | {result['seeds']} | " + " | ".join(cells) + " |"
                )
        return rows

    def transfer_rows(self) -> list[str]:
        """``wm-mpc`` on a model of another preset, as a markdown table."""
        rows = [
            "| tested in | model trained in | `wm-mpc` success | − `cv-mpc` (points, paired) | "
            "− `wm-mpc` on the preset's own model (points, paired) |",
            "|---|---|---|---|---|",
        ]
        for tested, sources in self.transfer.items():
            for trained, result in sources.items():
                cells = [_cell("success", result["success"])]
                for key in ("versus_physics", "versus_native"):
                    d = result.get(key)
                    cells.append("–" if d is None else f"{_interval(d)} (p {_p(d['p_value'])})")
                rows.append(f"| `{tested}` | `{trained}` | " + " | ".join(cells) + " |")
        return rows

    def split_rows(self) -> list[str]:
        """The planning model's error by interaction, as a markdown table."""
        ks = " | ".join(f"k = {k}" for k in SPLIT_KS)
        rows = [
            "Planning model − constant velocity, humans' error by what each human met in the "
            "window (cm, mean over rollouts with their 95% interval; negative: the model is "
            "nearer the truth), under the policy it plans with (`socnav-wm predict`):",
            "",
            f"| preset | policy | met | share at k = {SPLIT_KS[-1]} | constant velocity at "
            f"k = {SPLIT_KS[-1]} (m) | {ks} |",
            "|---|---|---|---|---|" + "---|" * len(SPLIT_KS),
        ]
        for preset, split in self.split.items():
            for name, part in split["interactions"].items():
                cells = [
                    "–"
                    if not math.isfinite(d)
                    else f"{100 * d:+.2f}"
                    if not (math.isfinite(low) and math.isfinite(high))
                    else f"{100 * d:+.2f} [{100 * low:+.2f}, {100 * high:+.2f}]"
                    for d, (low, high) in zip(
                        part["difference"], part["difference_ci"], strict=True
                    )
                ]
                met = name
                if name in split["near"]:
                    met = f"{name} within {split['distance']:g} m"
                rows.append(
                    f"| `{preset}` | `{split['policy']}` | {met} | {part['share']:.2f} | "
                    f"{part['error']:.3f} | " + " | ".join(cells) + " |"
                )
        return rows

    def published_rows(self) -> list[str]:
        rows = []
        for row in PUBLISHED:
            metrics = self.summaries.get(row.preset, {}).get(row.method)
            if metrics is None:
                continue
            success = metrics["success"]
            collision = metrics["human_collision"]["mean"]
            time = metrics["time_to_reach_goal"]["mean"]
            inside = success["low"] <= row.success <= success["high"]
            rows.append(
                f"| `{row.preset}` | `{row.method}` | {row.success:.2f} / {row.collision:.2f} / "
                f"{row.time:.2f} s | {success['mean']:.2f} [{success['low']:.2f}, "
                f"{success['high']:.2f}] / {collision:.2f} / {time:.2f} s | "
                f"{'yes' if inside else 'no'} |"
            )
        return rows

    def to_dict(self) -> dict[str, Any]:
        return {
            "summaries": self.summaries,
            "gaps": self.gaps,
            "missing": self.missing,
            "learned": self.learned,
            "transfer": self.transfer,
            "dqn": self.dqn,
            "model_gain": self.model_gain,
            "model_seeds": self.model_seeds,
            "split": self.split,
        }


def _cell(metric: str, summary: Mapping[str, float] | None) -> str:
    if summary is None or not math.isfinite(summary.get("mean", math.nan)):
        return "–"
    if not (math.isfinite(summary["low"]) and math.isfinite(summary["high"])):  # one sample
        scale = 1 if metric == "time_to_reach_goal" else 100
        return f"{scale * summary['mean']:.1f}"
    if metric == "time_to_reach_goal":
        return f"{summary['mean']:.1f} [{summary['low']:.1f}, {summary['high']:.1f}]"
    return f"{100 * summary['mean']:.1f} [{100 * summary['low']:.1f}, {100 * summary['high']:.1f}]"


def _interval(paired: Mapping[str, Any]) -> str:
    """A paired difference of :func:`_paired` as ``+d [+low, +high]`` (points)."""
    return f"{paired['difference']:+.1f} [{paired['low']:+.1f}, {paired['high']:+.1f}]"


def _p(value: float) -> str:
    return "–" if not math.isfinite(value) else ("< 0.001" if value < 0.001 else f"{value:.3f}")


def scenario_table(metrics_dir: Path, episodes_dir: Path, presets: Sequence[str]) -> ScenarioTable:
    """Every method of :data:`SCENARIO_METHODS` in every preset of ``presets`` that has a
    metrics file in ``metrics_dir/PRESET/``; the gap of every preset where both planners were
    evaluated, from their episodes in ``episodes_dir/PRESET/``.

    Raises:
        ValueError: no metrics file at all, a file that is not an evaluation's, or a preset
            whose planners have metrics but not their episodes (a fresh clone's: DVC's cache
            holds them), which would drop its gap from the table (one line naming it).
    """
    summaries: dict[str, dict[str, dict[str, dict[str, float]]]] = {}
    gaps: dict[str, dict[str, Any]] = {}
    learned: dict[str, dict[str, dict[str, Any]]] = {}
    transfer: dict[str, dict[str, dict[str, Any]]] = {}
    dqn: dict[str, dict[str, dict[str, Any]]] = {}
    split: dict[str, dict[str, Any]] = {}
    model_gain: dict[str, dict[str, Any]] = {}
    model_seeds: dict[str, dict[str, dict[str, Any]]] = {}
    missing: list[str] = []
    for preset in presets:
        prediction = metrics_dir / preset / "prediction.json"
        if prediction.is_file():
            split[preset] = _split(prediction)
        study = metrics_dir / preset / "dqn" / "results.parquet"
        if study.is_file():
            dqn[preset] = _agents(study)
        methods: dict[str, dict[str, dict[str, float]]] = {}
        for method in SCENARIO_METHODS + tuple(OTHER_PLANNERS):
            path = metrics_dir / preset / f"{OTHER_PLANNERS.get(method, method)}.json"
            if not path.is_file():
                if method in SCENARIO_METHODS:  # the others are where they were evaluated
                    missing.append(f"{preset}/{method}")
                continue
            methods[method] = _table_metrics(path)
        if methods:
            summaries[preset] = methods
        if "oracle-mpc" in methods and "cv-mpc" in methods:
            gap = f"oracle-mpc − cv-mpc gap of {preset}"
            oracle = _episodes(episodes_dir / preset / "oracle-mpc.parquet", gap)
            physics = _episodes(episodes_dir / preset / "cv-mpc.parquet", gap)
            gaps[preset] = _paired(oracle, physics)
            gaps[preset]["room"] = (
                gaps[preset]["difference"] >= GAP_POINTS and gaps[preset]["low"] > 0
            )
            others: dict[str, pa.Table] = {}  # read once: the transfers pair with wm-mpc too
            for name, stem in OTHER_PLANNERS.items():
                if name not in methods:
                    continue
                others[name] = _episodes(
                    episodes_dir / preset / f"{stem}.parquet",
                    f"{name} − cv-mpc difference of {preset}",
                )
                learned.setdefault(preset, {})[name] = {
                    "versus_physics": _paired(others[name], physics),
                    "versus_oracle": _paired(others[name], oracle),
                }
            if "wm-mpc-q" in others and "cv-mpc-q" in others:
                model_gain[preset] = _paired(others["wm-mpc-q"], others["cv-mpc-q"])
            seeds = sorted(
                (_model_seed(path.parent), path)
                for path in (metrics_dir / preset).glob(f"{MODEL_SEED_DIR}*/wm-mpc-q.json")
            )
            if seeds and "wm-mpc-q" in others:
                control = others.get("cv-mpc-q")
                runs = [("0", methods["wm-mpc-q"]["success"], others["wm-mpc-q"])]
                for seed, path in seeds:
                    episodes = _episodes(
                        episodes_dir / preset / path.parent.name / "wm-mpc-q.parquet",
                        f"wm-mpc-q on {preset}'s planning model of seed {seed}",
                    )
                    runs.append((str(seed), _table_metrics(path)["success"], episodes))
                model_seeds[preset] = {
                    seed: {
                        "success": success,
                        "versus_control": None if control is None else _paired(run, control),
                        "versus_physics": _paired(run, physics),
                    }
                    for seed, success, run in runs
                }
            native = others.get("wm-mpc")
            for path in sorted((metrics_dir / preset / TRANSFER_DIR).glob("*/wm-mpc.json")):
                trained = path.parent.name
                episodes = _episodes(
                    episodes_dir / preset / TRANSFER_DIR / trained / "wm-mpc.parquet",
                    f"transfer of {trained}'s model to {preset}",
                )
                transfer.setdefault(preset, {})[trained] = {
                    "success": _table_metrics(path)["success"],
                    "versus_physics": _paired(episodes, physics),
                    "versus_native": None if native is None else _paired(episodes, native),
                }
    if not summaries:
        raise ValueError(
            f"no scenario evaluation found in {metrics_dir} (run `dvc repro scenarios/dvc.yaml`)"
        )
    return ScenarioTable(
        summaries,
        gaps,
        missing,
        learned,
        transfer,
        dqn,
        model_gain=model_gain,
        model_seeds=model_seeds,
        split=split,
    )


def _model_seed(folder: Path) -> int:
    """The training seed in a ``model-seed-<S>`` folder's name (one line naming it if none)."""
    seed = folder.name.removeprefix(MODEL_SEED_DIR)
    if not seed.isdigit():
        raise ValueError(f"{folder}: expected a folder named {MODEL_SEED_DIR}<seed>, e.g. 1")
    return int(seed)


def _table_metrics(path: Path) -> dict[str, dict[str, float]]:
    """The :data:`TABLE_METRICS` of an evaluation's metrics file (one line naming the file
    when it is not one or lacks some)."""
    content = read_json(path)
    if not isinstance(content, dict) or not isinstance(content.get("metrics"), dict):
        raise ValueError(f"{path}: not an evaluation's metrics file (no `metrics`)")
    absent = [m for m, _ in TABLE_METRICS if m not in content["metrics"]]
    if absent:
        raise ValueError(f"{path}: lacks the metric(s) {', '.join(absent)}")
    return {m: content["metrics"][m] for m, _ in TABLE_METRICS}


def _agents(path: Path) -> dict[str, dict[str, Any]]:
    """Per agent variant of a preset's study, its finished runs' test metrics over seeds."""
    from socnav_wm.evaluation.intervals import mean_ci

    table = pq.read_table(path).to_pylist()
    absent = [m for m in ("variant", "status", *DQN_METRICS) if table and m not in table[0]]
    if absent:
        raise ValueError(f"{path}: lacks the column(s) {', '.join(absent)}")
    found: dict[str, dict[str, Any]] = {}
    for variant in dict.fromkeys(row["variant"] for row in table):
        runs = [r for r in table if r["variant"] == variant and r["status"] == "done"]
        if not runs:
            continue
        result: dict[str, Any] = {"seeds": len(runs)}
        for metric in DQN_METRICS:
            values = [float(r[metric]) for r in runs]
            mean, low, high, _, _ = mean_ci(values, confidence=0.95, method="t")
            result[metric] = {"mean": mean, "low": max(low, 0.0), "high": min(high, 1.0)}
        found[variant] = result
    return found


def _split(path: Path) -> dict[str, Any]:
    """The planning model's error by interaction at :data:`SPLIT_KS` from ``socnav-wm
    predict``'s output, under the planner's policy where it was measured, else the random one
    (one line naming the file when it has no planning model or no split)."""
    content = read_json(path)
    try:
        settings, policies = content["settings"], content["policies"]
        policy = settings.get("planner") or "random"
        errors = policies[policy]
        interactions, ks = errors["interactions"], errors["k"]
        versus, near = interactions["planning_model"], interactions["near"]
    except (KeyError, TypeError) as missing:
        raise ValueError(
            f"{path}: not a prediction with a planning model split by interaction "
            f"(no {missing}; socnav-wm predict --planning-model …)"
        ) from None
    absent = [k for k in SPLIT_KS if k not in ks]
    if absent:
        raise ValueError(f"{path}: no errors at k = {', '.join(map(str, absent))}")
    at = [ks.index(k) for k in SPLIT_KS]
    last = at[-1]
    cv = interactions["predictors"]["constant-velocity"]

    def number(value: float | None) -> float:  # the file writes NaN as null
        return math.nan if value is None else float(value)

    parts = {
        name: {
            "share": interactions["share"][name][last],
            "error": number(cv[name][last]),
            "difference": [number(versus[name]["difference"][i]) for i in at],
            "difference_ci": [
                [number(bound) for bound in versus[name]["difference_ci"][i]] for i in at
            ],
        }
        for name in interactions["share"]
        if (interactions["share"][name][last] or 0.0) > 0  # null: no rollout reached k
    }
    return {
        "policy": policy,
        "distance": interactions["distance"],
        "near": near,
        "k": list(SPLIT_KS),
        "interactions": parts,
    }


def _episodes(path: Path, needed_by: str) -> pa.Table:
    """An evaluation's episodes, read once per preset; one line naming the file and what needs
    it when it is not there (a fresh clone has the metrics, DVC's cache the episodes)."""
    if not path.is_file():
        raise ValueError(
            f"{path}: no such episodes file, and the paired {needed_by} needs it "
            "(dvc repro scenarios/dvc.yaml)"
        )
    return pq.read_table(path)


def _paired(first: pa.Table, second: pa.Table) -> dict[str, Any]:
    """The paired success difference ``first`` − ``second`` (episodes tables), in points."""
    result = compare(first, second, "success")
    return {
        "difference": 100 * result.difference,
        "low": 100 * result.low,
        "high": 100 * result.high,
        "p_value": result.p_value,
        "scenarios": result.num_scenarios,
    }
