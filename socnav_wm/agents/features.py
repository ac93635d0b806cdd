"""What each agent variant feeds its Q-network: the only place where the five variants differ.

A variant holds the frozen world model (VAE + LSTM, in eval mode, never optimised) and the
per-environment LSTM state ``(h, c)``. Each env step it turns ``(observation, world-model state,
action just taken)`` into the Q-network input and advances the state, for all environments in one
batched call (all candidate actions too, for the multi-action variants), under ``torch.no_grad``.

Notation (paper_spec §5): ``z = μ(o)`` is the VAE mean of the current observation (deterministic;
the paper sampled, §8.5); ``L(z, a, H) → (ẑ, H′)`` is one LSTM step, ``ẑ`` the predicted next
latent and ``H = (h, c)``; ``a`` is the action just taken, ``H`` the state carried from the
previous step. As in the paper's code, each real step feeds the LSTM the *current* latent with the
*action just taken*, and the state carried to the next step is ``H′ = L(z, a, H).state``.

==================  ====================================================  ==================
variant             Q-network input                                       size (L=16, H=256)
==================  ====================================================  ==================
dueling-dqn         the raw observation o                                 23
wm-dueling-dqn      z | h′                                                L + H = 272
2stepahead          z | h⁽ᵏ⁾: k steps with a repeated, each from the        L + H = 272
                    previous prediction (k = ``horizon``, 2 by default)
maspm               z | ẑ_0 | ẑ_1 | ẑ_2 | ẑ_3: ẑ_i = L(z, i, H), all from    L + 4L = 80
                    the same state
2stepahead-maspm    z | ẑ⁽ᵏ⁾_0..3: per action i, k steps with i repeated     L + 4L = 80
                    (hidden states h⁽ᵏ⁾_i instead with ``hidden_features``)  (L + 4H = 1040)
==================  ====================================================  ==================

Fixes of the original code (paper_spec §5, §8.1–8.3), each the paper's stated intent:
``maspm`` predicts every action from the same pre-update state (no ``.all()`` test);
``2stepahead-maspm`` rolls every action, not only the taken one, feeding the *predicted* latent to
the second step, and gives the Q-network latents by default; ``2stepahead`` carries the real
state ``H′`` and uses the imagined ``h⁽ᵏ⁾`` only as a feature (``carry_imagined=True`` carries the
imagined state, as the original did).

**The first step of an episode** (t = 0, no action taken yet) goes through the same formula with
``H = 0`` and the action ``stop``: the simulator starts the robot at rest, its last command is
(0, 0) — exactly the ``stop`` command — so "the robot was stopped" is the true history, and the
Q-network's input at t = 0 has the same meaning as at every other step (the paper's code instead
fed zeros in place of ``h`` or copies of ``z``, inputs the network never saw later in an episode).

With ``decode_latents`` every latent in the table (``z`` and the predicted ``ẑ``) reaches the
Q-network as the VAE decodes it, in observation units (23 values instead of 16; hidden states
stay as they are): the same information, in the geometry the raw observation has.

With ``sort_humans`` every variant first reorders the observation's humans nearest first
(:func:`sort_humans_by_distance`), before the VAE or the Q-network sees it.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch

from socnav_wm.agents.params import VARIANT_NAMES, AgentParams, check_variant
from socnav_wm.env.core import ACTION_NAMES, NUM_ACTIONS
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE

STOP = ACTION_NAMES.index("stop")
"""The action assumed to precede an episode's first observation (the robot starts at rest)."""


def sort_humans_by_distance(obs: torch.Tensor, features_per_human: int = 7) -> torch.Tensor:
    """Observations (B, 2 + 7·H) with the human blocks reordered nearest first.

    The simulator lists humans in spawn order (paper_spec §2, §8.15), so "the person about to
    hit me" can sit in any of the three slots and a Q-network has to learn its avoidance three
    times over. Ordering the blocks by robot–human distance (the first two entries of a block
    are the human's robot-frame position) gives every slot a meaning; ties keep spawn order.
    """
    num_humans = (obs.shape[1] - 2) // features_per_human
    if num_humans < 2:
        return obs
    humans = obs[:, 2:].reshape(obs.shape[0], num_humans, features_per_human)
    distance_sq = humans[..., 0].square() + humans[..., 1].square()
    order = distance_sq.argsort(dim=1, stable=True)
    humans = humans.gather(1, order.unsqueeze(-1).expand(-1, -1, features_per_human))
    return torch.cat([obs[:, :2], humans.flatten(1)], dim=1)


class WorldModelState(NamedTuple):
    """Per-env LSTM state: ``h`` and ``c``, each (num_envs, hidden_dim)."""

    h: torch.Tensor
    c: torch.Tensor


def _select_rows(state: WorldModelState, index: torch.Tensor) -> WorldModelState:
    return WorldModelState(state.h[index], state.c[index])


class Variant:
    """Base class: turns observations into Q-network features and keeps the per-env state.

    Use :meth:`reset` once when all environments start, then :meth:`step` after every vector
    step. Subclasses implement :meth:`compute`, a pure function of a batch.

    Args:
        vae, lstm: the frozen world model (ignored, and may be None, for ``dueling-dqn``).
        options: the agent's parameters; a variant reads its options from them (``horizon``,
            ``maspm_hidden_features``, ``carry_imagined``, ``sort_humans``,
            ``decode_latents``: :class:`~socnav_wm.agents.params.AgentParams` documents each),
            so a new option is one field there and its use here.
        obs_dim: size of the raw observation (23 for three humans).
        device: where the world model runs and the features live.
    """

    name: ClassVar[str]
    needs_world_model: ClassVar[bool] = True

    def __init__(
        self,
        vae: VAE | None = None,
        lstm: LatentLSTM | None = None,
        options: AgentParams | None = None,
        *,
        obs_dim: int = 23,
        device: torch.device | str = "cpu",
    ) -> None:
        self.options = options if options is not None else AgentParams()
        self.device = torch.device(device)
        self.obs_dim = int(obs_dim)
        self.vae: VAE | None = None
        self.lstm: LatentLSTM | None = None
        self.latent_dim = 0
        self.hidden_dim = 0
        if self.needs_world_model:
            if vae is None or lstm is None:
                raise ValueError(f"variant {self.name!r} needs the VAE and the LSTM world model")
            if vae.input_dim != self.obs_dim:
                raise ValueError(
                    f"the VAE reads {vae.input_dim}-d observations, the simulator gives "
                    f"{self.obs_dim}-d ones"
                )
            if vae.latent_dim != lstm.latent_dim:
                raise ValueError(
                    f"the VAE's latent has {vae.latent_dim} dims, the LSTM expects "
                    f"{lstm.latent_dim}"
                )
            if lstm.num_actions != NUM_ACTIONS:
                raise ValueError(
                    f"the LSTM was trained for {lstm.num_actions} actions, the robot has "
                    f"{NUM_ACTIONS}"
                )
            # Frozen: eval mode, no gradients, on the agent's device.
            self.vae = vae.to(self.device).eval().requires_grad_(False)
            self.lstm = lstm.to(self.device).eval().requires_grad_(False)
            self.latent_dim = lstm.latent_dim
            self.hidden_dim = lstm.hidden_dim
        # Size of one latent as the Q-network sees it (see shown()).
        self.shown_dim = self.obs_dim if self.options.decode_latents else self.latent_dim
        self.feature_dim = self._feature_dim()
        self.state: WorldModelState | None = None
        self.num_envs = 0

    # -- what subclasses define ----------------------------------------------------------------

    def _feature_dim(self) -> int:
        raise NotImplementedError

    def compute(
        self, z: torch.Tensor, actions: torch.Tensor, state: WorldModelState
    ) -> tuple[torch.Tensor, WorldModelState]:
        """Features and the carried state for a batch (pure; called under ``no_grad``).

        Args:
            z: (B, latent_dim) latents of the current observations (the raw observation for
                ``dueling-dqn``).
            actions: (B,) int64, the action just taken (``stop`` at an episode's start).
            state: the LSTM state before this step, each (B, hidden_dim).

        Returns:
            (features (B, feature_dim), state to carry to the next step).
        """
        raise NotImplementedError

    # -- batched driving -----------------------------------------------------------------------

    def _obs_tensor(self, obs: np.ndarray | torch.Tensor) -> torch.Tensor:
        obs_t = torch.as_tensor(obs, dtype=torch.float32).to(self.device)
        return sort_humans_by_distance(obs_t) if self.options.sort_humans else obs_t

    def zero_state(self, batch: int) -> WorldModelState:
        """All-zero LSTM state for ``batch`` envs (what every episode starts from)."""
        zeros = torch.zeros(batch, self.hidden_dim, device=self.device)
        return WorldModelState(zeros, zeros.clone())

    def shown(self, latents: torch.Tensor) -> torch.Tensor:
        """Latents (..., latent_dim) as the Q-network gets them: the code itself, or with
        ``decode_latents`` the VAE's decoding in raw observation units (..., obs_dim).

        Decoding adds no information (it is a fixed function of the code); it undoes the
        entanglement. The same learner gets 81% from the decoded current latent and 74% from
        the latent itself (README, "Where the world-model variants lose").
        """
        if not self.options.decode_latents or self.vae is None:
            return latents
        return self.vae.destandardize(self.vae.decode(latents))

    def encode(self, obs: torch.Tensor) -> torch.Tensor:
        """Raw observations (B, obs_dim) → latents (B, latent_dim) (the VAE mean)."""
        if self.vae is None:
            return obs
        return self.vae.encode(obs)[0]

    @torch.no_grad()
    def features(
        self, obs: np.ndarray | torch.Tensor, actions: np.ndarray | torch.Tensor, state: Any
    ) -> tuple[torch.Tensor, WorldModelState]:
        """Pure form of one step: (obs (B, obs_dim), actions (B,), state) → (features, state)."""
        obs_t = self._obs_tensor(obs)
        actions_t = torch.as_tensor(actions, dtype=torch.int64).to(self.device)
        return self.compute(self.encode(obs_t), actions_t, state)

    @torch.no_grad()
    def reset(self, obs: np.ndarray | torch.Tensor) -> torch.Tensor:
        """Every env starts an episode: zero state; returns the t = 0 features (N, feature_dim)."""
        num_envs = obs.shape[0]
        self.num_envs = num_envs
        stop = torch.full((num_envs,), STOP, dtype=torch.int64, device=self.device)
        features, self.state = self.features(obs, stop, self.zero_state(num_envs))
        return features

    @torch.no_grad()
    def step(
        self,
        next_obs: np.ndarray | torch.Tensor,
        actions: np.ndarray | torch.Tensor,
        reset_mask: np.ndarray | None = None,
        reset_obs: np.ndarray | torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Advance every env by one step; start new episodes in the envs of ``reset_mask``.

        Args:
            next_obs: (N, obs_dim) observations after the step (for an env whose episode just
                ended: its final observation).
            actions: (N,) the actions just taken.
            reset_mask: (N,) bool, envs whose episode ended and that now start a new one.
            reset_obs: (k, obs_dim) first observations of those new episodes (k = mask count).

        Returns:
            ``(next_features, features)``, each (N, feature_dim): the features of ``next_obs``
            (the replay's next state), and the features to act on now, which differ only in the
            reset envs (their new episode's t = 0 features, from a zeroed state). The carried
            state of the reset envs is their new episode's; the other envs' is advanced.
        """
        if self.state is None:
            raise RuntimeError("call reset(obs) before step()")
        obs_t = self._obs_tensor(next_obs)
        actions_t = torch.as_tensor(actions, dtype=torch.int64).to(self.device)
        state = self.state
        n = obs_t.shape[0]
        reset_index = None
        if reset_mask is not None and np.any(reset_mask):
            reset_index = torch.as_tensor(np.flatnonzero(reset_mask), device=self.device)
            k = reset_index.numel()
            if reset_obs is None or reset_obs.shape[0] != k:
                raise ValueError(f"reset_obs: expected {k} first observations")
            # One batched call for the continuing envs and the new episodes' first steps.
            obs_t = torch.cat([obs_t, self._obs_tensor(reset_obs)])
            stop = torch.full((k,), STOP, dtype=torch.int64, device=self.device)
            actions_t = torch.cat([actions_t, stop])
            zeros = self.zero_state(k)
            state = WorldModelState(torch.cat([state.h, zeros.h]), torch.cat([state.c, zeros.c]))
        features, new_state = self.compute(self.encode(obs_t), actions_t, state)
        next_features = features[:n]
        if reset_index is None:
            self.state = new_state
            return next_features, next_features
        current = next_features.clone()
        current[reset_index] = features[n:]
        h, c = new_state.h[:n].clone(), new_state.c[:n].clone()
        h[reset_index] = new_state.h[n:]
        c[reset_index] = new_state.c[n:]
        self.state = WorldModelState(h, c)
        return next_features, current

    def keep(self, rows: np.ndarray) -> None:
        """Keep the per-env state of ``rows`` alone, in that order (the other envs' episodes have
        ended and leave the batch); the next :meth:`step` gets the observations of ``rows``."""
        if self.state is None:
            raise RuntimeError("call reset(obs) before keep()")
        index = torch.as_tensor(np.asarray(rows, dtype=np.int64), device=self.device)
        self.state = _select_rows(self.state, index)
        self.num_envs = int(index.numel())

    # -- checkpoints ---------------------------------------------------------------------------

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The per-env LSTM state (CPU tensors); empty before :meth:`reset`."""
        if self.state is None:
            return {}
        return {"h": self.state.h.cpu().clone(), "c": self.state.c.cpu().clone()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        if not state:
            self.state = None
            return
        h, c = state["h"].to(self.device), state["c"].to(self.device)
        self.state = WorldModelState(h, c)
        self.num_envs = h.shape[0]


class DuelingDQNFeatures(Variant):
    """``dueling-dqn``: the raw 23-d observation, no world model."""

    name = "dueling-dqn"
    needs_world_model = False

    def _feature_dim(self) -> int:
        return self.obs_dim

    def compute(self, z, actions, state):
        return z, state


class WorldModelFeatures(Variant):
    """``wm-dueling-dqn``: ``z | h′`` with ``(ẑ, (h′, c′)) = L(z, a, H)``."""

    name = "wm-dueling-dqn"

    def _feature_dim(self) -> int:
        return self.shown_dim + self.hidden_dim

    def compute(self, z, actions, state):
        _, real = self.lstm.step(z, actions, state)
        real = WorldModelState(*real)
        return torch.cat([self.shown(z), real.h], dim=1), real


class StepAheadFeatures(Variant):
    """``2stepahead``: ``z | h⁽ᵏ⁾`` — ``horizon`` LSTM steps with the action just taken.

    The first step is the real one (``L(z, a, H)``); each further step feeds the previous
    prediction back with the same action. With ``horizon=1`` this is ``wm-dueling-dqn``.
    """

    name = "2stepahead"

    def _feature_dim(self) -> int:
        return self.shown_dim + self.hidden_dim

    def compute(self, z, actions, state):
        predicted, real = self.lstm.step(z, actions, state)
        real = WorldModelState(*real)
        imagined = real
        for _ in range(self.options.horizon - 1):
            predicted, imagined = self.lstm.step(predicted, actions, imagined)
            imagined = WorldModelState(*imagined)
        carried = imagined if self.options.carry_imagined else real
        return torch.cat([self.shown(z), imagined.h], dim=1), carried


class _MultiActionFeatures(Variant):
    """Shared by the MASPM variants: one rollout per candidate action from the same state."""

    def _rollouts(
        self, z: torch.Tensor, actions: torch.Tensor, state: WorldModelState, steps: int
    ) -> tuple[torch.Tensor, torch.Tensor, WorldModelState]:
        """Roll every action ``steps`` times (repeated), all from ``state``.

        Returns:
            (latents (B, A, L), hidden states (B, A, H) after ``steps`` steps, and the real
            state to carry: the taken action's first step, i.e. ``L(z, a, H)``).
        """
        batch = z.shape[0]
        predicted, (h, c) = self.lstm.step_all_actions(z, state)  # (B, A, L), (B, A, H)
        rows = torch.arange(batch, device=z.device)
        real = WorldModelState(h[rows, actions], c[rows, actions])
        if steps > 1:
            flat = batch * NUM_ACTIONS
            candidates = torch.arange(NUM_ACTIONS, device=z.device).repeat(batch)  # (B·A,)
            predicted = predicted.reshape(flat, -1)
            flat_state = (h.reshape(flat, -1), c.reshape(flat, -1))
            for _ in range(steps - 1):
                predicted, flat_state = self.lstm.step(predicted, candidates, flat_state)
            predicted = predicted.reshape(batch, NUM_ACTIONS, -1)
            h = flat_state[0].reshape(batch, NUM_ACTIONS, -1)
        return predicted, h, real

    def _shown_with_current(self, z: torch.Tensor, predicted: torch.Tensor) -> torch.Tensor:
        """``z | ẑ_0 | … | ẑ_3`` (B, (1 + A)·shown_dim), shown in one call of the decoder."""
        return self.shown(torch.cat([z.unsqueeze(1), predicted], dim=1)).flatten(1)


class MultiActionFeatures(_MultiActionFeatures):
    """``maspm``: ``z | ẑ_0 | … | ẑ_3`` with ``ẑ_i = L(z, i, H)``, all from the same ``H``."""

    name = "maspm"

    def _feature_dim(self) -> int:
        return self.shown_dim * (1 + NUM_ACTIONS)

    def compute(self, z, actions, state):
        predicted, _, real = self._rollouts(z, actions, state, steps=1)
        return self._shown_with_current(z, predicted), real


class StepAheadMultiActionFeatures(_MultiActionFeatures):
    """``2stepahead-maspm``: per action i, ``horizon`` steps with i repeated from ``H``.

    Features ``z | ẑ⁽ᵏ⁾_0..3`` (predicted latents), or ``z | h⁽ᵏ⁾_0..3`` with
    ``hidden_features``. With ``horizon=1`` and latents this is ``maspm``.
    """

    name = "2stepahead-maspm"

    def _feature_dim(self) -> int:
        per_action = self.hidden_dim if self.options.maspm_hidden_features else self.shown_dim
        return self.shown_dim + NUM_ACTIONS * per_action

    def compute(self, z, actions, state):
        predicted, hidden, real = self._rollouts(z, actions, state, steps=self.options.horizon)
        if self.options.maspm_hidden_features:
            return torch.cat([self.shown(z), hidden.flatten(1)], dim=1), real
        return self._shown_with_current(z, predicted), real


VARIANTS: dict[str, type[Variant]] = {
    cls.name: cls
    for cls in (
        DuelingDQNFeatures,
        WorldModelFeatures,
        StepAheadFeatures,
        MultiActionFeatures,
        StepAheadMultiActionFeatures,
    )
}
"""Variant name → class, in the paper's order."""
assert tuple(VARIANTS) == VARIANT_NAMES


def make_variant(
    name: str,
    vae: VAE | None = None,
    lstm: LatentLSTM | None = None,
    options: AgentParams | None = None,
    *,
    obs_dim: int = 23,
    device: torch.device | str = "cpu",
) -> Variant:
    """Build the variant ``name`` (see :data:`VARIANTS`) around a frozen world model."""
    return VARIANTS[check_variant(name)](vae, lstm, options, obs_dim=obs_dim, device=device)
