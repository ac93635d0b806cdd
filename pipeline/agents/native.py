"""The DQN update as one native call on the CPU (``agent.update_backend: native``).

:class:`NativeUpdate` does what :meth:`pipeline.agents.dqn.DQNLearner.update` does (forward
passes, Double-DQN target, loss, backward pass, gradient clipping, Adam, Polyak step) in one call
of ``native_update.c``, whose threads split each phase of the update between them instead of
splitting each of PyTorch's few dozen small operations (README "Speed"). It reads and writes the
learner's own flat buffers and the optimiser's own state tensors, so checkpoints, resuming and
agent files are those of the PyTorch update; the rounding is not, so a training changes with the
backend.

The C file is compiled on first use with the system's C compiler (``$CC``, else ``cc``) into
:func:`cache_dir` (``~/.cache/socnav-wm`` by default), under a name that hashes the source, the
flags, the compiler, PyTorch and the CPU, and written atomically. Its matrix products are the
``sgemm_`` of the MKL inside PyTorch's CPU library (x86-64 builds of PyTorch).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from pipeline.agents.dqn import DQNLearner
    from pipeline.agents.replay import Batch

SOURCE = Path(__file__).with_name("native_update.c")
FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fopenmp", "-shared", "-fPIC")
PARTS = 2
"""native_update.c's PARTS: every phase of the update is cut into this many parts, one thread each
(so at most this many threads are used, and the result does not depend on how many are)."""
MAX_TRUNK_LAYERS = 64
"""native_update.c's MAX_LAYERS."""


class NativeUpdateError(ValueError):
    """The native update cannot be built or used here (the message says why)."""


def _torch_library_dir() -> Path:
    return Path(torch.__file__).parent / "lib"


def _cpu_signature() -> str:
    """What -march=native compiles for: the CPU's model and flags (Linux), else the platform."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("flags", "Features")):
                return line
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cache_dir() -> Path:
    """Where builds go: ``$SOCNAV_WM_CACHE_DIR``, else ``$XDG_CACHE_HOME/socnav-wm``."""
    if os.environ.get("SOCNAV_WM_CACHE_DIR"):
        return Path(os.environ["SOCNAV_WM_CACHE_DIR"])
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "socnav-wm"


def _compiler() -> str:
    """The C compiler: ``$CC`` if set, else ``cc`` or ``gcc`` on the PATH (full path)."""
    wanted = os.environ.get("CC")
    found = shutil.which(wanted) if wanted else shutil.which("cc") or shutil.which("gcc")
    if found:
        return found
    if wanted:
        raise NativeUpdateError(f"agent.update_backend: native: C compiler {wanted!r} not found")
    raise NativeUpdateError(
        "agent.update_backend: native needs a C compiler with OpenMP ($CC, cc or gcc); none "
        "was found (install gcc, or use update_backend: torch)"
    )


@functools.cache
def load_library() -> ctypes.CDLL:
    """Compile ``native_update.c`` if this machine has no build of it yet, and load it."""
    lib_dir = _torch_library_dir()
    torch_cpu = lib_dir / "libtorch_cpu.so"
    try:
        ctypes.CDLL(str(torch_cpu)).sgemm_  # noqa: B018 - the lookup is the check
    except (OSError, AttributeError):
        raise NativeUpdateError(
            f"agent.update_backend: native needs MKL's sgemm_ in {torch_cpu} (PyTorch's x86-64 "
            "Linux builds); this PyTorch has none (use update_backend: torch)"
        ) from None
    compiler = _compiler()
    version = subprocess.run(
        [compiler, "--version"], capture_output=True, text=True, check=False
    ).stdout
    key = "\n".join(
        (SOURCE.read_text(), " ".join(FLAGS), compiler, version, torch.__version__, str(lib_dir),
         _cpu_signature())
    )  # fmt: skip
    target = cache_dir() / f"native_update-{hashlib.sha256(key.encode()).hexdigest()[:16]}.so"
    if not target.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".native_update-", suffix=".so")
        os.close(fd)
        command = [
            compiler, *FLAGS, str(SOURCE), "-o", tmp, f"-L{lib_dir}", "-ltorch_cpu",
            f"-Wl,-rpath,{lib_dir}",
        ]  # fmt: skip
        built = subprocess.run(command, capture_output=True, text=True, check=False)
        if built.returncode != 0:
            Path(tmp).unlink(missing_ok=True)
            last = (built.stderr.strip().splitlines() or ["no output"])[-1]
            raise NativeUpdateError(
                f"agent.update_backend: native: compiling {SOURCE.name} with {compiler} failed: "
                f"{last}"
            )
        os.replace(tmp, target)  # atomic: a concurrent build of the same key is identical
    lib = ctypes.CDLL(str(target))
    pointer = ctypes.c_void_p
    lib.native_workspace.restype = ctypes.c_long
    lib.native_workspace.argtypes = [pointer, ctypes.c_int]
    lib.native_update.restype = ctypes.c_double
    lib.native_update.argtypes = [ctypes.c_int, pointer, ctypes.c_int, *[pointer] * 16]
    lib.native_update.argtypes += [ctypes.c_long, pointer]
    return lib


class NativeUpdate:
    """:meth:`DQNLearner.update` for ``learner`` (on the CPU) in one native call.

    Args:
        learner: the learner whose networks, flat buffers and optimiser the update uses.
    """

    def __init__(self, learner: DQNLearner) -> None:
        self.lib = load_library()
        self.learner = learner
        net = learner.q_network
        if len(net._trunk) > MAX_TRUNK_LAYERS:
            raise NativeUpdateError(
                f"agent.trunk_sizes: the native update takes at most {MAX_TRUNK_LAYERS} layers"
            )
        base = learner._weights.data_ptr()
        offset = {id(p): (p.data_ptr() - base) // p.element_size() for p in net.parameters()}

        def at(layer: torch.nn.Linear) -> list[int]:
            return [offset[id(layer.weight)], offset[id(layer.bias)]]

        layout = [len(net._trunk), net.stream_size, net.num_actions]
        for layer in net._trunk:
            layout += [*at(layer), layer.in_features, layer.out_features]
        for stream in (net._value, net._advantage):
            layout += at(stream[0]) + at(stream[1])
        self.layout = np.asarray(layout, dtype=np.int64)
        group = learner.optimizer.param_groups[0]
        self.beta1, self.beta2 = (float(b) for b in group["betas"])
        p = learner.params
        self.hyper = np.zeros(9, dtype=np.float32)
        self.hyper[:7] = (
            p.learning_rate, self.beta1, self.beta2, group["eps"], p.polyak, p.grad_clip,
            p.weight_decay,
        )  # fmt: skip
        self.flags = np.asarray([p.huber, p.amsgrad, p.optimizer == "adamw"], dtype=np.int32)
        self.partials = np.zeros(2 * PARTS, dtype=np.float64)
        self.norm = np.zeros(1, dtype=np.float32)
        self.workspace = torch.empty(0)
        self.workspace_rows = 0  # the largest batch the workspace holds
        self._state()  # the optimiser's state, created as torch's fused Adam creates it

    def _state(self) -> dict[str, torch.Tensor]:
        """The optimiser's state of the flat buffer (a resumed run replaces the tensors)."""
        learner = self.learner
        state = learner.optimizer.state[learner._weights]
        if not state:
            weights = learner._weights
            state["step"] = torch.zeros((), dtype=torch.float32)
            state["exp_avg"] = torch.zeros_like(weights)
            state["exp_avg_sq"] = torch.zeros_like(weights)
            if learner.params.amsgrad:
                state["max_exp_avg_sq"] = torch.zeros_like(weights)
        return state

    def __call__(self, batch: Batch) -> torch.Tensor:
        """One update on ``batch``; returns the loss (before the step), as the PyTorch update."""
        learner = self.learner
        if batch.actions.dtype != torch.int64 or batch.features.dtype != torch.float32:
            raise NativeUpdateError(
                "the native update takes float32 features and int64 actions, got "
                f"{batch.features.dtype} and {batch.actions.dtype}"
            )
        n = batch.features.shape[0]
        if n > self.workspace_rows:  # the workspace grows with the batch; sized once per size
            self.workspace = torch.empty(self.lib.native_workspace(self.layout.ctypes.data, n))
            self.workspace_rows = n
        threads = min(torch.get_num_threads(), PARTS)
        state = self._state()
        state["step"] += 1
        step = float(state["step"])
        self.hyper[7] = 1.0 - self.beta1**step
        self.hyper[8] = 1.0 - self.beta2**step
        moments = state.get("max_exp_avg_sq", state["exp_avg_sq"])
        columns = [
            batch.features.contiguous(), batch.next_features.contiguous(),
            batch.actions.contiguous(), batch.rewards.contiguous(),
            batch.terminals.contiguous(), batch.discounts.contiguous(),
        ]  # fmt: skip
        loss = self.lib.native_update(
            threads, self.layout.ctypes.data, n,
            learner._weights.data_ptr(), learner._target_weights.data_ptr(),
            learner._grads.data_ptr(), state["exp_avg"].data_ptr(),
            state["exp_avg_sq"].data_ptr(), moments.data_ptr(), self.workspace.data_ptr(),
            *(column.data_ptr() for column in columns),
            self.hyper.ctypes.data, self.flags.ctypes.data, self.partials.ctypes.data,
            learner._weights.numel(), self.norm.ctypes.data,
        )  # fmt: skip
        return torch.tensor(loss, dtype=torch.float32)
