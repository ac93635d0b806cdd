"""Benchmarks: speed and memory of the pipeline's hot paths, measured, never asserted.

Each benchmark returns rows (dicts) that ``socnav-wm bench …`` prints as a table. Timings run
after a warm-up (numba compilation, first allocations), for a fixed wall-clock budget per row,
pinned to one CPU core where the OS allows it so that numbers from different machines compare.
"""

from __future__ import annotations

import os
import time
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

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


def _rate(step: Callable[[], int], seconds: float) -> float:
    """Items per second of ``step`` (which returns how many items it did) over ``seconds``."""
    done = 0
    start = time.perf_counter()
    while True:
        done += step()
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
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
    policy: str, n: int, seed: int, actions: np.ndarray
) -> tuple[Any, Callable[[], int]]:
    """A reset env and a function doing one step of it that returns the env-steps done."""
    import gymnasium as gym

    import pipeline.env  # noqa: F401  (registers SocNav-v0)

    cursor = [0]
    if n == 1:
        env = gym.make("SocNav-v0", human_policy=policy)
        env.reset(seed=seed)

        def single_step() -> int:
            action = int(actions[cursor[0] % len(actions), 0])
            cursor[0] += 1
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
            return 1

        return env, single_step
    envs = gym.make_vec("SocNav-v0", num_envs=n, human_policy=policy)
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
) -> list[dict[str, Any]]:
    """Env-steps per second of random-action stepping, with autoreset, no rendering.

    Batch 1 goes through ``gym.make("SocNav-v0")`` (with gymnasium's default wrappers: what a
    user of the single env gets); larger batches through ``gym.make_vec("SocNav-v0", N)``.
    ``peak_mb`` is the peak of traced allocations (numpy arrays included) from building the env
    through 20 steps: the simulator's own memory, not the interpreter's.
    """
    rows = []
    for policy in policies:
        for n in batch_sizes:
            actions = np.random.default_rng(seed).integers(0, 4, size=(16, n))
            env, step = _env_stepper(policy, n, seed, actions)
            for _ in range(20):  # warm-up: compilation, caches
                step()
            rate = _rate(step, seconds)
            env.close()

            def lifecycle(policy=policy, n=n, actions=actions) -> None:
                env, step = _env_stepper(policy, n, seed, actions)
                for _ in range(20):
                    step()
                env.close()

            rows.append(
                {
                    "humans": policy,
                    "batch": n,
                    "interface": "gym.make" if n == 1 else "gym.make_vec",
                    "steps_per_s": rate,
                    "peak_mb": _peak_bytes(lifecycle) / 2**20,
                }
            )
    return rows


def bench_collect(
    episodes: int = 2000, num_envs: tuple[int, ...] = (256, 512), seed: int = 0
) -> list[dict[str, Any]]:
    """End-to-end speed of the collect stage: simulation, buffering and Parquet writing."""
    import tempfile
    from pathlib import Path

    from pipeline.data.collect import collect_rollouts
    from pipeline.env.params import EnvParams

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        # Warm-up: compiled kernels and pyarrow's first-use costs are not part of the rate.
        collect_rollouts(
            EnvParams(), episodes=8, num_envs=8, seed=seed, out_dir=Path(tmp) / "warm",
            max_rows_per_shard=400_000,
        )  # fmt: skip
        for n in num_envs:
            out = Path(tmp) / f"n{n}"
            summary = collect_rollouts(
                EnvParams(), episodes=episodes, num_envs=n, seed=seed, out_dir=out,
                max_rows_per_shard=400_000,
            )  # fmt: skip
            size = sum(path.stat().st_size for path in summary.shards)
            rows.append(
                {
                    "episodes": summary.episodes,
                    "num_envs": n,
                    "steps": summary.steps,
                    "seconds": summary.seconds,
                    "steps_per_s": summary.steps / summary.seconds,
                    "parquet_mb": size / 2**20,
                }
            )
    return rows
