"""The parameters of the ORCA and Social Force robots (``params.yaml``'s ``baselines`` section).

Apart from the controllers (:mod:`socnav_wm.agents.baselines`), so that the configuration can
validate them without importing a robot controller.
"""

from __future__ import annotations

import math
from typing import ClassVar

from pydantic import Field, field_validator

from socnav_wm.section import Section, non_negative, positive

__all__ = ["BaselinesParams", "OrcaBaselineParams", "SfmBaselineParams"]


class OrcaBaselineParams(Section):
    """The ORCA robot's parameters. Lengths in metres, times in seconds, angles in radians.

    The defaults suit this scenario rather than RVO2's examples: everyone moves at ≤ 0.14 m/s
    in 1 s steps, so 5 s of look-ahead covers 1.4 m of closing distance between the robot and a
    person walking towards it.
    """

    SECTION: ClassVar[str] = "baselines.orca"
    name: ClassVar[str] = "orca"

    neighbor_dist: float = positive(4.0)
    """Humans whose centre is closer than this to the robot's are avoided (m)."""
    max_neighbors: int = Field(10, gt=0)
    """At most this many nearest humans are avoided (more than the room holds by default)."""
    time_horizon: float = positive(5.0)
    """Collisions with humans are avoided over this horizon (s)."""
    time_horizon_obst: float = positive(2.0)
    """Collisions with walls are avoided over this horizon (s); walls do not move, so a short
    horizon keeps the robot from being pushed off goals near a wall."""
    safety_margin: float = non_negative(0.2)
    """Added to the robot's radius in ORCA (m). The humans do not reciprocate (none sees the
    robot, except SFM humans 5% of the time) while ORCA assumes they take half of the
    avoidance, and they turn towards new goals without warning, so the robot keeps a buffer.
    On 400 scenarios of a tuning seed (not the evaluation's), 0 m gave 25% human collisions,
    0.1 m 5%, 0.2 m 3%, and more did not help."""
    symmetry_bias: float = Field(0.02, allow_inf_nan=False)
    """Angle (rad) by which the preferred velocity is turned to the right. RVO2's examples add a
    small random perturbation to break the perfect symmetry of a head-on encounter, where the
    preferred velocity lies on the velocity obstacle's axis and ORCA only slows down; a fixed
    turn to the right does the same deterministically (and passes people on the robot's left,
    the "keep right" convention)."""
    heading_gain: float = non_negative(1.0)
    """Fraction of the heading error turned in one step (see :func:`unicycle_command`)."""

    @field_validator("symmetry_bias")
    @classmethod
    def _small_bias(cls, value: float) -> float:
        if abs(value) >= math.pi / 2:
            raise ValueError(f"must be within ±π/2, got {value!r}")
        return value


class SfmBaselineParams(Section):
    """The Social Force robot's parameters (Helbing & Molnár 1995; Helbing et al. 2000).

    Forces are per unit mass (m/s²). Helbing's pedestrian values (A = 2000 N / 80 kg ≈ 25 m/s²,
    B = 0.08 m, τ = 0.5 s) are for people walking at 1.3 m/s and updated every few ms; here
    everyone moves at ≤ 0.14 m/s in 1 s steps, so the strengths are scaled down to the robot's
    speed and the ranges up to the distance covered in a few steps.
    """

    SECTION: ClassVar[str] = "baselines.sfm"
    name: ClassVar[str] = "sfm"

    relaxation_time: float = positive(1.0)
    """τ of the goal attraction (v0·e_goal − v)/τ (s). The relaxation is integrated exactly over
    a step (v → v0·e + (v − v0·e)·exp(−dt/τ)), which stays stable for τ < dt too."""
    human_strength: float = non_negative(0.4)
    """A of the human repulsion A·exp((r_ij − d_ij)/B)·n_ij (m/s²), r_ij the sum of radii and
    d_ij the centre distance: the push at contact."""
    human_range: float = positive(0.4)
    """B of the human repulsion (m): the push falls by e for every B of clearance."""
    wall_strength: float = non_negative(0.4)
    """A of the wall repulsion A·exp((r − d)/B)·n (m/s²), d the distance to the wall face."""
    wall_range: float = positive(0.1)
    """B of the wall repulsion (m). Short: goals may lie 0.3 m from a wall."""
    anisotropy: float = Field(0.3, allow_inf_nan=False)
    """λ of Helbing's field of view: a human straight ahead weighs 1, one behind the robot
    weighs λ (weight λ + (1 − λ)(1 + cos φ)/2, φ the angle between the goal direction and the
    direction to the human)."""
    side_bias: float = non_negative(0.5)
    """Sideways share of the push from a human ahead of the robot, turning it to its right
    (Helbing & Molnár's "keep right" asymmetry). Without it a person standing on the straight
    line to the goal pushes exactly against the goal attraction and the robot stops in front of
    them; it scales with cos φ (zero for humans beside or behind)."""
    heading_gain: float = non_negative(1.0)
    """Fraction of the heading error turned in one step (see :func:`unicycle_command`)."""

    @field_validator("anisotropy")
    @classmethod
    def _in_unit(cls, value: float) -> float:
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"must be in [0, 1], got {value!r}")
        return value


class BaselinesParams(Section):
    """The ORCA and Social Force robots' parameters (socnav_wm/agents/baselines.py documents
    each, and how it was chosen)."""

    SECTION: ClassVar[str] = "baselines"

    orca: OrcaBaselineParams = Field(default_factory=OrcaBaselineParams)
    """The ORCA robot (:class:`~socnav_wm.agents.baselines.OrcaBaselineParams`)."""
    sfm: SfmBaselineParams = Field(default_factory=SfmBaselineParams)
    """The Social Force robot (:class:`~socnav_wm.agents.baselines.SfmBaselineParams`)."""
