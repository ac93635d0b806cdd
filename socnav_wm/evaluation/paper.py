"""The paper's target numbers and claims, as data (paper_spec §7), with provenance and uncertainty.

The numbers come from the UKCI 2023 PDF: test results were read off the histograms of Figs. 7–8
(pixel heights calibrated on the y-tick labels; about ±3 episodes for counts out of 500, and
±half a histogram bin for means), training plateaus from Fig. 6 and the author's thesis. Several
test metrics were computed differently by the authors' scripts than by this project (paper_spec
§6): each value says which of our metrics it corresponds to and whether the definitions agree,
so that the report compares like with like and says so when it cannot.

Nothing here computes anything; :mod:`socnav_wm.evaluation.claims` holds the logic that checks
:data:`CLAIMS` against a run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = [
    "ANY_COLLISION",
    "BASELINE_NOTE",
    "CLAIMS",
    "PAPER_EPISODES",
    "PAPER_METHOD_NAMES",
    "TEST_TARGETS",
    "TRAINING_TARGETS",
    "Claim",
    "PaperValue",
    "TrainingTarget",
]

PAPER_EPISODES = 500
"""Test episodes per method in the paper."""

ANY_COLLISION = "any_collision"
"""Pseudo-metric: ``human_collision + wall_collision``. The authors' collision flag fired on any
collision, walls included (paper_spec §6), so their "human collisions" compare with this."""

PAPER_METHOD_NAMES: dict[str, str] = {
    "dueling-dqn": "Vanilla Dueling DQN",
    "wm-dueling-dqn": "WM Dueling DQN",
    "2stepahead": "2StepAhead",
    "maspm": "MASPM",
    "2stepahead-maspm": "2StepAhead-MASPM",
    "orca": "RVO2 (ORCA)",
    "sfm": "SFM",
}
"""Our method names → the names in the paper's figures."""

BASELINE_NOTE = (
    "The paper's RVO2 and SFM robots were not the textbook controllers: its scripts mixed the "
    "robot and world frames, fed ORCA a 2 m robot radius, ignored walls and sent raw velocities "
    "as (v, ω) (paper_spec §6, §8.13). Ours are textbook ORCA and Social Force controllers with "
    "a unicycle conversion, built to succeed far more often than the paper's 43% and 58% (see "
    "this run's table), so the claims that the DQN agents beat the baselines are tested here "
    "against a different, much stronger pair of baselines."
)


@dataclass(frozen=True)
class PaperValue:
    """One number the paper reports for one method and metric.

    Attributes:
        value: the paper's value, in our metric's unit (rates as fractions of episodes).
        our_metric: which of our per-episode columns it compares with (a name of
            ``socnav_wm.metrics.ALL_METRICS`` or :data:`ANY_COLLISION`); compared by the mean.
        uncertainty: ± half-width of the reading error, same unit (None: unknown).
        comparable: whether the paper's definition matches ours closely enough for the numbers
            to be compared directly.
        source: where the number comes from.
        note: what differs, when something does.
    """

    value: float
    our_metric: str
    uncertainty: float | None
    comparable: bool
    source: str
    note: str = ""


_FIGS = "UKCI-PDF Figs. 7–8, read from the histograms"
_COUNT_ERROR = 3.0 / PAPER_EPISODES  # ±3 episodes out of 500


def _rate(count: float, metric: str, note: str = "", *, exact: bool = False) -> PaperValue:
    """A count out of 500 episodes as a rate."""
    return PaperValue(
        value=count / PAPER_EPISODES,
        our_metric=metric,
        uncertainty=0.0 if exact else _COUNT_ERROR,
        comparable=True,
        source=_FIGS + (" (exact: equals the y-tick label)" if exact else ""),
        note=note,
    )


def _mean(value: float, metric: str, comparable: bool, note: str = "") -> PaperValue:
    # Means were estimated from bin centres: ±half a bin, whose width the figures do not state.
    return PaperValue(value, metric, None, comparable, _FIGS + " (bin-centre mean)", note)


_COLLISION_NOTE = "the paper's flag counted wall collisions too; compared with human + wall"
_DISCOMFORT_NOTE = "steps with dmin < 0.9999 m; ours also counts the terminal step"
_SIM_TIME_NOTE = "mean over the values shown in the histogram only (some were cut off)"
_AGENT_IDLE_NOTE = "the paper's scripts counted stop actions, ours counts steps moving < 0.05 m"
_BASELINE_IDLE_NOTE = "the paper's baseline scripts counted unchanged lagged positions (≥ 1)"
_AGENT_PSC_NOTE = "code definition (centre distance ≥ 2.02 m): our personal_space_compliance_code"
_BASELINE_PSC_NOTE = "the baseline scripts indexed the wrong observation entries: meaningless"


def _agent_row(
    success: float, collisions: float, discomfort: float, sim_time: float, idle: float
) -> dict[str, PaperValue]:
    return {
        "success": _rate(success, "success"),
        "any_collision": _rate(collisions, ANY_COLLISION, _COLLISION_NOTE),
        "max_steps": _rate(0, "max_steps"),
        "discomfort": _mean(discomfort, "discomfort", True, _DISCOMFORT_NOTE),
        "simulation_time": _mean(sim_time, "simulation_time", True),
        "idle_time": _mean(idle, "idle_time", False, _AGENT_IDLE_NOTE),
    }


TEST_TARGETS: dict[str, dict[str, PaperValue]] = {
    "orca": {
        "success": _rate(215, "success"),
        "any_collision": _rate(267, ANY_COLLISION, _COLLISION_NOTE),
        "max_steps": _rate(19, "max_steps"),
        "discomfort": _mean(8.8, "discomfort", True, _DISCOMFORT_NOTE),
        "simulation_time": _mean(53.0, "simulation_time", True, _SIM_TIME_NOTE),
        "idle_time": _mean(1.3, "idle_time", False, _BASELINE_IDLE_NOTE),
        "personal_space_compliance_code": _mean(
            0.73, "personal_space_compliance_code", False, _BASELINE_PSC_NOTE
        ),
    },
    "sfm": {
        "success": _rate(288, "success"),
        "any_collision": _rate(208, ANY_COLLISION, _COLLISION_NOTE),
        "max_steps": _rate(6, "max_steps"),
        "discomfort": _mean(6.3, "discomfort", True, _DISCOMFORT_NOTE),
        "simulation_time": _mean(42.0, "simulation_time", True),
        "idle_time": _mean(1.0, "idle_time", False, _BASELINE_IDLE_NOTE),
        "personal_space_compliance_code": _mean(
            0.69, "personal_space_compliance_code", False, _BASELINE_PSC_NOTE
        ),
    },
    "dueling-dqn": {
        **_agent_row(435, 64, 6.1, 42.0, 0.45),
        "personal_space_compliance_code": _mean(
            0.60, "personal_space_compliance_code", True, _AGENT_PSC_NOTE
        ),
    },
    "wm-dueling-dqn": {
        **_agent_row(441, 58, 5.7, 40.0, 0.25),
        "personal_space_compliance_code": _mean(
            0.62, "personal_space_compliance_code", True, _AGENT_PSC_NOTE
        ),
    },
    "maspm": _agent_row(457, 44, 6.1, 40.0, 0.42),
    "2stepahead": {
        **_agent_row(446, 53, 11.4, 37.0, 0.0),
        "success": _rate(446, "success", exact=True),
    },
    "2stepahead-maspm": {
        **_agent_row(472, 28, 5.6, 41.0, 0.3),
        "success": _rate(472, "success", exact=True),
        "personal_space_compliance_code": _mean(
            0.63, "personal_space_compliance_code", True, _AGENT_PSC_NOTE
        ),
    },
}
"""Method → {row label → the paper's value}. Row labels are our metric names, except
``any_collision`` (:data:`ANY_COLLISION`). The paper's distance histograms are left out: the
DQN scripts summed changes of the robot-frame goal vector, which rotations inflate (≈15–18
"m" for the agents against ≈4–5 m for the baselines), so they compare with nothing of ours."""


@dataclass(frozen=True)
class TrainingTarget:
    """The paper's smoothed training return of one variant (Fig. 6; THESIS §5.3.1).

    Attributes:
        plateau: the final level of the smoothed return per episode.
        start: its level at the first episodes (Fig. 6, by eye).
        source: where it comes from; the smoothing window is unknown.
    """

    plateau: float
    start: float
    source: str


TRAINING_TARGETS: dict[str, TrainingTarget] = {
    "dueling-dqn": TrainingTarget(0.52, -0.45, "THESIS §5.3.1 (Fig. 6: ≈0.52–0.57)"),
    "wm-dueling-dqn": TrainingTarget(0.61, -0.40, "UKCI-PDF Fig. 6, by eye"),
    "maspm": TrainingTarget(0.64, -0.27, "UKCI-PDF Fig. 6, by eye"),
    "2stepahead": TrainingTarget(0.65, -0.17, "UKCI-PDF Fig. 6, by eye"),
    "2stepahead-maspm": TrainingTarget(0.67, -0.22, 'paper §4.1 ("0.67"), Fig. 6'),
}
"""Variant → its training curve in the paper (x axis 0–180k episodes, ours is shorter)."""


ClaimKind = Literal["better", "best", "pareto", "rank", "training-better", "training-fastest"]


@dataclass(frozen=True)
class Claim:
    """One of the paper's claims, stated so that a run can confirm or contradict it.

    Attributes:
        claim_id: short stable key (used in ``metrics/report.json``).
        statement: the claim in words, as the report prints it.
        source: where the paper makes it.
        kind: how it is checked (see :mod:`socnav_wm.evaluation.claims`):
            ``better``: each ``subject`` beats each ``other`` on each metric (paired tests);
            ``best``: the subject beats every other evaluated method on each metric;
            ``pareto``: the subject is Pareto non-dominated over the nine metrics (means);
            ``rank``: the subject's rank among all seven methods equals ``ranks[metric]``;
            ``training-better``: the subjects' training plateaus exceed the others';
            ``training-fastest``: the subject reaches the solved criterion first.
        subjects, others: method names (``others`` empty for ``best``, ``pareto``, ``rank``,
            where the rest of the methods is meant).
        metrics: our metric names the claim is about.
        ranks: for ``rank`` claims, the paper's rank (1 = best) per metric.
    """

    claim_id: str
    statement: str
    source: str
    kind: ClaimKind
    subjects: tuple[str, ...]
    others: tuple[str, ...] = ()
    metrics: tuple[str, ...] = ()
    ranks: tuple[tuple[str, int], ...] = ()


_WM_VARIANTS = ("wm-dueling-dqn", "2stepahead", "maspm", "2stepahead-maspm")
_AGENTS = ("dueling-dqn", *_WM_VARIANTS)

CLAIMS: tuple[Claim, ...] = (
    Claim(
        "best-success",
        "2StepAhead-MASPM has the highest success rate of all methods (94.4%)",
        "paper §4.2, §5; Figs. 7–8",
        "best",
        ("2stepahead-maspm",),
        metrics=("success",),
    ),
    Claim(
        "twostep-maspm-beats-dqn",
        "2StepAhead-MASPM improves on vanilla Dueling DQN in success rate, human collisions and "
        "cumulative reward",
        "paper §4.2, §5",
        "better",
        ("2stepahead-maspm",),
        ("dueling-dqn",),
        ("success", "human_collision", "reward"),
    ),
    Claim(
        "world-models-beat-dqn",
        "Every world-model variant reaches a higher success rate than vanilla Dueling DQN "
        "(88–94% against 87%)",
        'paper §4.1 ("significant improvements … over the baseline"); Figs. 7–8',
        "better",
        _WM_VARIANTS,
        ("dueling-dqn",),
        ("success",),
    ),
    Claim(
        "agents-beat-baselines-success",
        "The DQN agents reach a higher success rate than ORCA (RVO2) and SFM "
        "(87–94% against 43% and 58%)",
        "paper §4.2; Fig. 8",
        "better",
        _AGENTS,
        ("orca", "sfm"),
        ("success",),
    ),
    Claim(
        "agents-collide-less-than-baselines",
        "The DQN agents collide with humans less often than ORCA (RVO2) and SFM "
        "(28–64 against 267 and 208 of 500)",
        "paper §4.2; Fig. 8",
        "better",
        _AGENTS,
        ("orca", "sfm"),
        ("human_collision",),
    ),
    Claim(
        "twostep-maspm-pareto",
        "2StepAhead-MASPM is Pareto non-dominated: no other method is better on every metric",
        "paper §4.2",
        "pareto",
        ("2stepahead-maspm",),
    ),
    Claim(
        "twostep-maspm-ranks",
        "2StepAhead-MASPM ranks second in idle time and third in personal space compliance, "
        "simulation time and distance travelled (of seven methods)",
        "paper §4.2",
        "rank",
        ("2stepahead-maspm",),
        ranks=(
            ("idle_time", 2),
            ("personal_space_compliance", 3),
            ("simulation_time", 3),
            ("distance_travelled", 3),
        ),
    ),
    Claim(
        "training-twostep-maspm-highest",
        "2StepAhead-MASPM reaches the highest smoothed training return (0.67)",
        "paper §4.1; Fig. 6",
        "training-better",
        ("2stepahead-maspm",),
        ("dueling-dqn", "wm-dueling-dqn", "2stepahead", "maspm"),
    ),
    Claim(
        "training-world-models-higher",
        "The world-model variants' training returns plateau higher than vanilla Dueling DQN's "
        "(0.61–0.67 against 0.52)",
        "paper §4.1; Fig. 6; THESIS §5.3.1",
        "training-better",
        _WM_VARIANTS,
        ("dueling-dqn",),
    ),
    Claim(
        "training-twostep-fastest",
        '2StepAhead learns fastest ("solves the task in about 3200 episodes")',
        "paper §4.1; Fig. 6",
        "training-fastest",
        ("2stepahead",),
        ("dueling-dqn", "wm-dueling-dqn", "maspm", "2stepahead-maspm"),
    ),
)
"""The claims the report checks, in the order it prints them."""
