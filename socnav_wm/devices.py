"""Where tensors live: the one place that turns a device setting (``auto``, ``cpu``, ``cuda``)
into a ``torch.device``."""

from __future__ import annotations

import numpy as np
import torch


def resolve_device(device: torch.device | str) -> torch.device:
    """``torch.device`` from a device or a name; ``"auto"`` picks CUDA when available.

    Raises:
        ValueError: CUDA is asked for and this PyTorch has no CUDA device to give.
    """
    if isinstance(device, str) and device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    resolved = torch.device(device)
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            f"device {str(device)!r}: CUDA is not available here (torch {torch.__version__}); "
            "use auto or cpu"
        )
    return resolved


def as_tensor(array: np.ndarray | torch.Tensor, device: torch.device) -> torch.Tensor:
    """float32 tensor on ``device``; tensors are moved, never round-tripped through numpy."""
    if isinstance(array, torch.Tensor):
        return array.to(device=device, dtype=torch.float32)
    return torch.as_tensor(np.asarray(array, dtype=np.float32), device=device)
