"""The planners' parameters (``params.yaml``'s ``planning`` section): a light module, no torch.

:mod:`socnav_wm.planning.mpc` explains the planner; each field below says what it changes.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import AfterValidator, BeforeValidator, Field, model_validator

from socnav_wm.section import Section, Seed, as_tuple, finite, seed_field

PLANNER_NAMES: tuple[str, ...] = ("cv-mpc", "wm-mpc", "vae-lstm-mpc", "oracle-mpc", "wm-mpc-q")
"""The planning methods: receding-horizon control over the paper's four actions, each with its
model of the goal and the humans: ``cv-mpc`` constant velocity (no learning), ``wm-mpc`` the
planning world model (``train_planning_model``'s seed 0), ``vae-lstm-mpc`` the paper's VAE +
LSTM, ``oracle-mpc`` the simulator itself (the ceiling of the four actions); ``wm-mpc-q`` is
``wm-mpc`` with a trained agent as its critic: the agent's value at the horizon, its greedy
actions as the ``policy`` continuation (:mod:`socnav_wm.planning.critic`)."""

MAX_PREFIXES = 1024
"""The most prefixes a planner scores (each with every continuation)."""
Continuation = Literal["goal", "stop", "forward", "policy"]
ActionSet = Literal["paper", "lattice"]
CONTINUATIONS: tuple[str, ...] = ("goal", "stop", "forward")


def _distinct(value: tuple[str, ...]) -> tuple[str, ...]:
    if not value:
        raise ValueError("expected at least one continuation")
    if len(set(value)) != len(value):
        raise ValueError(f"a continuation is listed twice in {list(value)!r}")
    return value


Continuations = Annotated[
    tuple[Continuation, ...], BeforeValidator(as_tuple), AfterValidator(_distinct)
]


class PlanningParams(Section):
    """Receding-horizon planning over the paper's four actions (socnav_wm/planning/mpc.py).

    At every step the planner scores every candidate, a ``prefix_length``-action prefix (all
    ``4**prefix_length`` of them) followed by one of the ``continuations`` up to ``horizon``
    steps, on the model's predicted goal and humans, and executes the first action of the best.
    """

    SECTION: ClassVar[str] = "planning"

    horizon: int = Field(12, gt=0)
    """Steps each candidate is predicted ahead."""
    prefix_length: int = Field(3, gt=0, le=5)
    """Length of the exhaustive prefix (A**prefix_length candidates for A actions; at most
    1,024)."""
    actions: ActionSet = "paper"
    """What the robot is commanded: ``paper``, the four discrete actions; ``lattice``, a lattice
    of continuous commands (``lattice_speeds`` × ``lattice_headings``, and stop): (v, ω) for the
    unicycle, velocities (vx, vy) in every direction for the holonomic robot. Only the planners
    whose model takes continuous commands (``cv-mpc``, ``oracle-mpc``) plan over a lattice."""
    lattice_speeds: int = Field(2, ge=1, le=5)
    """``lattice``: the non-zero speeds, evenly up to the robot's maximum."""
    lattice_headings: int = Field(8, ge=2, le=16)
    """``lattice``: the turn rates, evenly in ±the robot's maximum (unicycle), or the
    directions, evenly round the circle (holonomic)."""
    continuations: Continuations = CONTINUATIONS
    """What follows a prefix: ``goal`` (turn towards the predicted goal, then advance), ``stop``,
    ``forward``; ``policy``, the critic's greedy action on each imagined observation (a planner
    with a critic only: ``wm-mpc-q``)."""
    discount: float = finite(0.95, gt=0, le=1)
    """Weight γᵏ of step k's terms: the same outcome sooner scores higher."""
    goal_reward: float = finite(10.0, ge=0)
    """Added once when the predicted robot reaches the goal (the candidate's end)."""
    collision_cost: float = finite(10.0, ge=0)
    """Subtracted once when a predicted human touches the robot (the candidate's end)."""
    discomfort_cost: float = finite(0.1, ge=0)
    """Subtracted per step where a predicted human is nearer than the scenario's
    ``discomfort_distance`` (0.9999 m, the paper's) surface to surface."""
    progress_weight: float = finite(1.0, ge=0)
    """Weight of each step's progress towards the goal (metres)."""
    value_weight: float = finite(1.0, ge=0)
    """A planner with a critic (``wm-mpc-q``): a candidate still running at the horizon gains
    ``value_weight · γ^horizon · max_a Q(ô, a)``, the critic's value of its imagined last
    observation ``ô``. The agent's return is about +1 for the goal and −1 for a failure, so 10
    would weigh it as ``goal_reward`` and ``collision_cost``; with the critics trained here that
    hands the robot to the agent (docs/scenarios.md), hence 1."""
    safety_margin: float = finite(0.0, ge=0)
    """Added to the radii when testing a predicted contact (m)."""
    walls: bool = True
    """The planner knows the room and the robot's pose in it (a map and localisation, which
    the ORCA and SFM robots and ``oracle-mpc`` have too): a candidate whose imagined robot
    touches a wall collides there. False: it sees only what the observation shows (no walls)."""
    oracle_seed: Seed = seed_field(4_000_037)
    """``oracle-mpc``: the seed of its clones' random draws (SFM noticing the robot, the humans'
    new goals), not the episode's: it knows the humans' rules, not their future coin flips."""
    oracle_clairvoyant: bool = False
    """``oracle-mpc``: the clones reuse the episode's own draws instead (a clairvoyant ceiling)."""
    oracle_reactions: bool = True
    """``oracle-mpc``: false, the clones' humans do not react to the robot (whatever
    ``env.humans_see_robot``): what knowing their reaction is worth to the ceiling."""
    per_method: dict[str, dict[str, Any]] = Field(
        default_factory=lambda: {
            "vae-lstm-mpc": {"prefix_length": 2, "horizon": 6},
            "wm-mpc-q": {"continuations": [*CONTINUATIONS, "policy"]},
        }
    )
    """Per-planner overrides of the fields above. ``vae-lstm-mpc`` runs a 256-unit LSTM and the
    VAE's decoder for every candidate and step, 40–75 ms of one core per decision at the shared
    64 candidates × 12 steps; its 16 × 6 keep a 500-scenario evaluation within minutes.
    ``wm-mpc-q`` adds the ``policy`` continuation to the shared ones."""

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        self._check_overrides("per_method", PLANNER_NAMES, "planner")
        candidates = self.num_actions**self.prefix_length
        if candidates > MAX_PREFIXES:
            raise ValueError(
                f"prefix_length: {self.num_actions} actions over {self.prefix_length} steps make "
                f"{candidates:,} prefixes, more than {MAX_PREFIXES:,}"
            )
        return self

    @property
    def num_actions(self) -> int:
        """A: the paper's 4, or the lattice's commands (stop included; for the unicycle the
        speeds include 0, turning in place)."""
        if self.actions == "paper":
            return 4
        return (self.lattice_speeds + 1) * self.lattice_headings

    def resolved(self, method: str) -> PlanningParams:
        """The values planner ``method`` uses: ``self`` with ``per_method[method]`` applied (and
        ``per_method`` emptied)."""
        if method not in PLANNER_NAMES:
            raise ValueError(
                f"unknown planner {method!r}; expected one of {', '.join(PLANNER_NAMES)}"
            )
        return self._overridden("per_method", method)
