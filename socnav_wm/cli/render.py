"""``socnav-wm render``: episodes of any robot policy as an animated GIF."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from socnav_wm.cli.application import UserError, command
from socnav_wm.cli.options import SharedOptions, shared_options
from socnav_wm.layout import LAYOUT, agent_file


@command()
@shared_options("params", "set", "overlay")
def render(
    *,
    out: Annotated[Path, typer.Option(help="Animated GIF to write.")] = LAYOUT.episode_gif,
    policy: Annotated[
        str,
        typer.Option(
            help="Robot policy: random, orca, sfm, a planner (cv-mpc, wm-mpc, vae-lstm-mpc, "
            "oracle-mpc: their models at the pipeline's paths), a variant (its seed-0 agent in "
            "--agents-dir) or the path of an agent file."
        ),
    ] = "random",
    scenario: Annotated[
        list[int] | None, typer.Option(min=0, help="Scenario ids to show (repeatable).")
    ] = None,
    episodes: Annotated[
        int, typer.Option(min=1, help="Without --scenario: scenarios 0..episodes-1.")
    ] = 3,
    seed: Annotated[int, typer.Option(min=0, help="Scenario seed.")] = 0,
    human_policy: Annotated[
        str | None,
        typer.Option(
            help="Human motion: mixed, sfm or orca "
            "\\[default: env.human_policy of the params file]."
        ),
    ] = None,
    agents_dir: Annotated[
        Path, typer.Option(help="Agents folder for a variant name.")
    ] = LAYOUT.agents_dir,
    options: SharedOptions,
    fps: Annotated[float, typer.Option(min=0.5, help="Frames per second.")] = 8.0,
    size: Annotated[int, typer.Option(min=64, help="Frame side in pixels.")] = 480,
) -> None:
    """Render episodes of any robot policy (random, a baseline, a planner, a trained agent) in
    the simulator as an animated GIF, on chosen scenarios."""
    from socnav_wm.method_names import METHOD_NAMES

    as_file = Path(policy)
    named = ("random", *METHOD_NAMES)
    if policy not in named and as_file.suffix != ".pt":
        choices = ", ".join(named)
        raise UserError(f"--policy: unknown {policy!r}; expected {choices} or an agent file (.pt)")
    from socnav_wm.section import check_seed

    check_seed(seed, "--seed")
    import numpy as np

    from socnav_wm.env.core import MAX_SCENARIO_ID
    from socnav_wm.env.frames import write_gif
    from socnav_wm.env.render import episode_frames
    from socnav_wm.env.rollout import random_policy, run_episodes

    for scenario_id in scenario or ():
        if scenario_id >= MAX_SCENARIO_ID:
            raise UserError(
                f"--scenario: scenario ids are below 2**62 (the simulator's), got {scenario_id}"
            )

    config = options.load_or_defaults()
    params = config.env if human_policy is None else config.env.replace(human_policy=human_policy)
    ids = np.asarray(scenario if scenario else range(episodes), dtype=np.int64)
    if policy == "random":
        runs = run_episodes(params, random_policy(seed), seed, ids)
    elif policy in METHOD_NAMES:
        from socnav_wm.methods import method

        chosen = method(policy, "--policy")
        sections = {name: getattr(config, name) for name in chosen.sections}
        if "eval" in sections:  # an agent's network runs on the CPU here
            sections["eval"] = sections["eval"].replace(device="cpu")
        files = {"agent": agent_file(agents_dir, policy, 0)} if chosen.kind == "agent" else None
        act, reads_simulator = chosen.configured(params, sections, files)()
        runs = run_episodes(params, act, seed, ids, reads_simulator=reads_simulator)
    else:
        from socnav_wm.agents.agent_file import greedy_episodes, load_agent

        agent = load_agent(as_file, env_params=params)
        runs = greedy_episodes(agent, params, seed=seed, scenario_ids=ids)
    frames = []
    for episode in runs:
        frames += episode_frames(episode, params, label=policy if len(policy) < 24 else "agent",
                                 size=size)  # fmt: skip
    write_gif(frames, out, fps=fps)
    outcomes = ", ".join(
        "success" if e.success else f"{e.collision} collision" if e.collision else "timeout"
        for e in runs
    )
    typer.echo(f"wrote {out} ({len(frames)} frames; {outcomes})")
