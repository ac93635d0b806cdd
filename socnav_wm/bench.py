"""Benchmarks: speed and memory of the pipeline's hot paths, measured, never asserted.

Each benchmark returns rows (dicts) that ``socnav-wm bench …`` prints as a table. Timings run
after a warm-up (numba compilation, first allocations), for a fixed wall-clock budget per row.
The simulator and collection benchmarks are pinned to one CPU core where the OS allows it, so
that numbers from different machines compare; the training benchmark uses the threads torch is
given, as a training does.
"""

from __future__ import annotations

import itertools
import os
import time
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from socnav_wm.agents.params import AgentParams
    from socnav_wm.env.params import EnvParams

ENV_BATCH_SIZES = (1, 64, 1024, 4096)
ENV_POLICIES = ("sfm", "orca", "mixed")


@contextmanager
def one_core() -> Iterator[str]:
    """Pin this process to one CPU core for the duration (where the OS supports it)."""
    if not hasattr(os, "sched_getaffinity"):
        yield "unpinned"
        return
    before = os.sched_getaffinity(0)
    core = min(before)
    os.sched_setaffinity(0, {core})
    try:
        yield f"core {core}"
    finally:
        os.sched_setaffinity(0, before)


def _rate(
    step: Callable[[], int], seconds: float, synchronize: Callable[[], None] | None = None
) -> float:
    """Items per CPU-second of this process (``time.process_time``: every thread's CPU time,
    so neighbours on a shared machine do not change it) of ``step``, which returns how many
    items it did, over ``seconds`` CPU-seconds.

    ``synchronize`` (``torch.cuda.synchronize`` on a GPU) waits for the work ``step`` queued,
    before the clock starts and before it stops.
    """
    if synchronize is not None:
        synchronize()
    done = 0
    start = time.process_time()
    while True:
        done += step()
        elapsed = time.process_time() - start
        if elapsed >= seconds:
            if synchronize is not None:
                synchronize()
                elapsed = time.process_time() - start
            return done / elapsed


def _peak_bytes(run: Callable[[], None]) -> int:
    """Peak traced allocation (numpy arrays included) while ``run`` executes."""
    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _env_stepper(
    options: dict[str, Any], n: int, seed: int, actions: np.ndarray
) -> tuple[Any, Callable[[], int]]:
    """A reset env of ``options`` (EnvParams fields) and a function doing one step of it that
    returns the env-steps done."""
    import gymnasium as gym

    import socnav_wm  # noqa: F401  (registers SocNav-v0)

    cursor = [0]
    if n == 1:
        env = gym.make("SocNav-v0", **options)
        env.reset(seed=seed)

        def single_step() -> int:
            action = int(actions[cursor[0] % len(actions), 0])
            cursor[0] += 1
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
            return 1

        return env, single_step
    envs = gym.make_vec("SocNav-v0", num_envs=n, **options)
    envs.reset(seed=seed)

    def batch_step() -> int:
        envs.step(actions[cursor[0] % len(actions)])
        cursor[0] += 1
        return n

    return envs, batch_step


def bench_env(
    batch_sizes: tuple[int, ...] = ENV_BATCH_SIZES,
    policies: tuple[str, ...] = ENV_POLICIES,
    seconds: float = 2.0,
    seed: int = 0,
    scenarios: dict[str, dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Env-steps per second of random-action stepping, with autoreset, no rendering.

    Batch 1 goes through ``gym.make("SocNav-v0")`` (with gymnasium's default wrappers: what a
    user of the single env gets); larger batches through ``gym.make_vec("SocNav-v0", N)``.
    ``peak_mb`` is the peak of traced allocations (numpy arrays included) from building the env
    through 20 steps: the simulator's own memory, not the interpreter's. Rows per human policy
    of the paper's scenario, or, given ``scenarios`` (name → EnvParams fields: a preset), per
    scenario with its own humans, or per scenario and policy where ``policies`` is not empty.
    """
    presets = scenarios is not None
    if scenarios is None:
        runs = [("paper", {"human_policy": policy}) for policy in policies]
    elif policies:
        runs = [
            (name, {**options, "human_policy": policy})
            for name, options in scenarios.items()
            for policy in policies
        ]
    else:
        runs = list(scenarios.items())
    rows = []
    for name, options in runs:
        for n in batch_sizes:
            actions = np.random.default_rng(seed).integers(0, 4, size=(16, n))
            env, step = _env_stepper(options, n, seed, actions)
            for _ in range(20):  # warm-up: compilation, caches
                step()
            rate = _rate(step, seconds)
            env.close()

            def lifecycle(options=options, n=n, actions=actions) -> None:
                env, step = _env_stepper(options, n, seed, actions)
                for _ in range(20):
                    step()
                env.close()

            row = {"humans": options.get("human_policy", "mixed"), "batch": n}
            if presets:  # a preset: its name and obstacles instead of the interface
                row = {
                    "scenario": name,
                    **row,
                    "obstacles": _count_range(options, "tables", "plants"),
                }
            else:
                row["interface"] = "gym.make" if n == 1 else "gym.make_vec"
            row |= {"steps_per_cpu_s": rate, "peak_mb": _peak_bytes(lifecycle) / 2**20}
            rows.append(row)
    return rows


def _count_range(options: dict[str, Any], *names: str) -> str:
    """``low–high`` of the sum of count ranges ``names`` of ``options`` (0 when absent)."""
    low = sum(options.get(name, (0, 0))[0] for name in names)
    high = sum(options.get(name, (0, 0))[1] for name in names)
    return f"{low}–{high}" if high != low else str(low)


COLLECT_MAX_EPISODES = 100_000
"""The most episodes a row of ``bench collect`` runs: a few minutes of one core (about 7 million
steps), and a few GiB of Parquet at most in the temporary folder."""


def bench_collect(
    episodes: int = 2000, num_envs: tuple[int, ...] = (256, 512), seed: int = 0
) -> list[dict[str, Any]]:
    """End-to-end speed of the collect stage (simulation, buffering and Parquet writing), per
    CPU-second of this process.

    Raises:
        ValueError: ``episodes`` beyond :data:`COLLECT_MAX_EPISODES`, or more Parquet than the
            temporary folder's disk has room for (one line, before any work).
    """
    import tempfile
    from pathlib import Path

    from socnav_wm.data.collect import collect_rollouts
    from socnav_wm.env.observation_layout import observation_size
    from socnav_wm.env.params import EnvParams
    from socnav_wm.resources import check_disk

    if not 1 <= episodes <= COLLECT_MAX_EPISODES:
        raise ValueError(
            f"--episodes: must be in 1..{COLLECT_MAX_EPISODES:,} (a benchmark row of minutes), "
            f"got {episodes:,}"
        )
    env = EnvParams()
    row_bytes = 8 * (2 * observation_size(env.num_humans) + 8 + 2 * env.num_humans)
    most = episodes * env.max_steps * row_bytes  # every episode at its longest, uncompressed
    check_disk("--episodes", most, tempfile.gettempdir(), f"{episodes:,} episodes")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        # Warm-up: compiled kernels and pyarrow's first-use costs are not part of the rate.
        collect_rollouts(
            EnvParams(), episodes=8, num_envs=8, seed=seed, out_dir=Path(tmp) / "warm",
            max_rows_per_shard=400_000,
        )  # fmt: skip
        for n in num_envs:
            out = Path(tmp) / f"n{n}"
            cpu_start = time.process_time()
            summary = collect_rollouts(
                EnvParams(), episodes=episodes, num_envs=n, seed=seed, out_dir=out,
                max_rows_per_shard=400_000,
            )  # fmt: skip
            cpu_seconds = time.process_time() - cpu_start
            size = sum(path.stat().st_size for path in summary.shards)
            rows.append(
                {
                    "episodes": summary.episodes,
                    "num_envs": n,
                    "steps": summary.steps,
                    "cpu_seconds": cpu_seconds,
                    "steps_per_cpu_s": summary.steps / cpu_seconds,
                    "parquet_mb": size / 2**20,
                }
            )
    return rows


def bench_train(
    variant: str,
    *,
    params: AgentParams | None = None,
    env_params: EnvParams | None = None,
    seconds: float = 3.0,
    latent_dim: int = 16,
    vae_hidden_dim: int = 256,
    lstm_hidden_dim: int = 256,
) -> dict[str, Any]:
    """Env-steps/s (acting + simulator + features + storing) and gradient updates/s, measured
    separately, with a random-initialised world model of the given sizes (the paper's by
    default).

    ``params`` is the ``agent`` section the training would use (``per_variant`` is applied
    here); ``num_envs`` environments are stepped together and each update reads ``batch_size``
    transitions. Returns ``{"variant", "feature_dim", "num_envs", "batch_size",
    "env_steps_per_cpu_s", "updates_per_cpu_s"}``, per CPU-second of the process. Each rate is
    measured for ``seconds`` CPU-seconds after a short
    warm-up.
    """
    import torch

    from socnav_wm.agents.agent_file import variant_for
    from socnav_wm.agents.features import VARIANTS
    from socnav_wm.agents.learner import DQNLearner
    from socnav_wm.agents.params import AgentParams, check_variant
    from socnav_wm.agents.replay import ReplayBuffer
    from socnav_wm.agents.training import step_and_restart
    from socnav_wm.devices import resolve_device
    from socnav_wm.env.core import NUM_ACTIONS, Simulator
    from socnav_wm.env.params import EnvParams
    from socnav_wm.worldmodel.lstm import LatentLSTM
    from socnav_wm.worldmodel.vae import VAE

    check_variant(variant)
    env_params = env_params or EnvParams()
    p = (params or AgentParams()).resolved(variant)
    num_envs, batch_size = p.num_envs, p.batch_size
    p = p.replace(
        learning_starts=batch_size,  # the benchmark calls the update itself
        buffer_size=max(p.buffer_size, num_envs, batch_size),
    )
    target = resolve_device(p.device)
    torch.manual_seed(0)
    sim = Simulator(num_envs, env_params)
    vae = lstm = None
    if VARIANTS[variant].needs_world_model:
        vae = VAE(sim.obs_dim, vae_hidden_dim, latent_dim)
        lstm = LatentLSTM(latent_dim, NUM_ACTIONS, lstm_hidden_dim)
    features_of = variant_for(variant, vae, lstm, p, obs_dim=sim.obs_dim, device=target)
    learner = DQNLearner(features_of.feature_dim, p, target)
    replay = ReplayBuffer(p.buffer_size, features_of.feature_dim, target, seed=0)
    rng = np.random.default_rng(0)

    obs, _ = sim.reset(seed=0)
    state = {"features": features_of.reset(obs)}

    def env_step() -> int:
        actions = learner.act(state["features"], 0.5, rng)
        step = step_and_restart(sim, features_of, actions)
        replay.add(
            state["features"], actions, step.result.reward, step.next_features,
            step.result.terminated, p.gamma,
        )  # fmt: skip
        state["features"] = step.features
        return num_envs

    def update() -> int:
        learner.update(replay.sample(batch_size))
        return 1

    synchronize = torch.cuda.synchronize if target.type == "cuda" else None

    def rate(step: Callable[[], int]) -> float:
        for _ in range(5):  # warm-up
            step()
        return _rate(step, seconds, synchronize)

    env_rate = rate(env_step)
    while len(replay) < batch_size:
        env_step()
    update_rate = rate(update)
    return {
        "variant": variant,
        "feature_dim": features_of.feature_dim,
        "num_envs": num_envs,
        "batch_size": batch_size,
        "env_steps_per_cpu_s": env_rate,
        "updates_per_cpu_s": update_rate,
    }


CONTENTION_STAGE_SETTINGS: tuple[str, ...] = (
    "collect.episodes=1000",
    "vae.max_epochs=3",
    "vae.patience=3",
    "vae.device=cpu",
    "lstm.max_epochs=2",
    "lstm.patience=2",
    "lstm.device=cpu",
    "agent.episodes=300",
    "agent.eval_episodes=50",
    "agent.select_every=0",
    "agent.device=cpu",
    "planning_model.max_epochs=1",
)
"""The stages' runs in :func:`bench_contention`: the shipped networks, trained briefly on 1000
random episodes (a few to some tens of CPU-seconds each)."""

CONTENTION_STAGES: dict[str, tuple[str, ...]] = {
    "train-vae": ("train-vae",),
    "train-lstm": ("train-lstm",),
    "train-agent": ("train-agent", "--variant", "wm-dueling-dqn"),
    "train-planning-model": ("train-planning-model", "--seed", "0"),
}
"""The torch stages :func:`bench_contention` can measure, as ``socnav-wm`` arguments."""


def _child_cpu_seconds(command: list[str], cwd: str, env: dict[str, str]) -> tuple[float, float]:
    """(CPU-seconds, wall seconds) of one child process run to its end (``os.wait4``'s rusage:
    every thread of the child, user + system)."""
    import subprocess

    start = time.perf_counter()
    child = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited with status {child.returncode}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - start


def bench_contention(
    threads: tuple[int, ...],
    hogs: int,
    repeats: int = 1,
    settings: tuple[str, ...] = CONTENTION_STAGE_SETTINGS,
    stages: tuple[str, ...] = ("train-vae",),
) -> list[dict[str, Any]]:
    """CPU-seconds of each of ``stages`` (:data:`CONTENTION_STAGES`) alone and beside ``hogs``
    busy processes (``yes > /dev/null``), for each torch thread count.

    A stage whose threads spin while waiting for a core (OpenMP's busy wait) burns CPU-seconds
    the work does not need when the cores are shared; the ratio says by how much. Each stage
    runs as its own process (``socnav-wm STAGE --no-tracking``) in a temporary folder, on data
    that ``socnav-wm collect`` (and, for the stages that read them, ``train-vae`` and
    ``train-lstm``) write there first, all with ``settings`` (``--set`` overrides of the
    defaults). Each row is the fastest of ``repeats``.

    Raises:
        ValueError: a stage that is not one of :data:`CONTENTION_STAGES`.
    """
    for name in stages:
        if name not in CONTENTION_STAGES:
            raise ValueError(
                f"--stage: unknown {name!r}; expected one of {', '.join(CONTENTION_STAGES)}"
            )
    import subprocess
    import sys
    import tempfile

    cli = [sys.executable, "-m", "socnav_wm.cli"]
    options = [f"--set={s}" for s in settings]
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    rows = []
    with tempfile.TemporaryDirectory(prefix="socnav-wm-contention-") as work:
        open(os.path.join(work, "params.yaml"), "w").close()  # every default
        needs = {"train-lstm": ["train-vae"], "train-agent": ["train-vae", "train-lstm"]}
        made = ["collect", *dict.fromkeys(m for name in stages for m in needs.get(name, []))]
        for step in made:  # the inputs, once
            _child_cpu_seconds([*cli, step, "--no-tracking", "--quiet", *options], work, env)
        for name, n in itertools.product(stages, threads):
            stage = [*cli, *CONTENTION_STAGES[name], "--no-tracking", "--quiet", f"--threads={n}",
                     *options]  # fmt: skip
            alone = min(_child_cpu_seconds(stage, work, env) for _ in range(repeats))
            busy = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(hogs)]
            try:
                shared = min(_child_cpu_seconds(stage, work, env) for _ in range(repeats))
            finally:
                for hog in busy:
                    hog.kill()
                    hog.wait()
            rows.append(
                {
                    "stage": name,
                    "threads": n,
                    "omp_wait_policy": env.get("OMP_WAIT_POLICY", "(default)"),
                    "gomp_spincount": env.get("GOMP_SPINCOUNT", "(default)"),
                    "hogs": hogs,
                    "cpu_s_alone": alone[0],
                    "cpu_s_shared": shared[0],
                    "ratio": shared[0] / alone[0],
                    "wall_s_alone": alone[1],
                    "wall_s_shared": shared[1],
                }
            )
    return rows


PLAN_BATCH_SIZES = (1, 64, 512)


def bench_plan(
    methods: tuple[str, ...],
    batch_sizes: tuple[int, ...] = PLAN_BATCH_SIZES,
    *,
    env_params: EnvParams,
    planning: Any,
    files: dict[str, dict[str, Any]] | None = None,
    seconds: float = 2.0,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Decisions per CPU-second of each planner with ``n`` episodes planned together.

    Each call of a planner's policy plans one step of every episode of the batch; an episode
    that ends is replaced by the next scenario of ``seed``, so the batch stays full. The first
    calls (compilation, first allocations) are not timed. ``cpu_ms_per_decision`` is the
    process's CPU time per decision (one core when torch has one thread).

    Args:
        methods: planner names (:data:`socnav_wm.planning.params.PLANNER_NAMES`; the registry,
            :mod:`socnav_wm.methods`, builds them).
        batch_sizes: the ``n`` of each row.
        env_params: the scenarios' parameters.
        planning: the ``planning`` section.
        files: each learned planner's model files by role (default: the pipeline's paths).
    """
    from socnav_wm.env.core import Simulator
    from socnav_wm.methods import method as lookup

    rows = []
    for method in methods:
        planner = lookup(method)
        policies = planner.policies(
            env_params, files=planner.files((files or {}).get(method)), planning=planning
        )
        for n in batch_sizes:
            sim = Simulator(n, env_params)
            obs, _ = sim.reset(seed=seed)
            policy, reads_simulator = policies()
            state = {"obs": obs}

            def decide(sim=sim, policy=policy, reads_simulator=reads_simulator, state=state, n=n):
                actions = policy(sim if reads_simulator else state["obs"])
                sim.step(actions)
                state["obs"] = sim.autoreset(sim.state.done)
                return n

            for _ in range(2):  # warm-up
                decide()
            rate = _rate(decide, seconds)
            resolved = planning.resolved(method)
            rows.append(
                {
                    "planner": method,
                    "futures": 4**resolved.prefix_length * len(resolved.continuations),
                    "horizon": resolved.horizon,
                    "envs": n,
                    "decisions_per_cpu_s": rate,
                    "cpu_ms_per_decision": 1000.0 / rate,
                }
            )
    return rows
