"""What each variant feeds the Q-network, checked against hand-driven world-model calls."""

import numpy as np
import pytest
import torch

from socnav_wm.agents.features import (
    STOP,
    VARIANTS,
    WorldModelState,
    make_variant,
    sort_humans_by_distance,
)
from socnav_wm.agents.params import AgentParams
from socnav_wm.env import EnvParams, Simulator
from tests.agents.conftest import HIDDEN, LATENT, OBS_DIM, tiny_world_model

NUM_ENVS = 5


def observations(steps: int = 4, seed: int = 0) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Real observations of ``steps`` random steps of 5 envs (obs list has steps + 1 entries)."""
    sim = Simulator(NUM_ENVS, EnvParams())
    obs, _ = sim.reset(seed=seed)
    rng = np.random.default_rng(seed)
    all_obs, all_actions = [obs], []
    for _ in range(steps):
        actions = rng.integers(0, 4, NUM_ENVS)
        all_obs.append(sim.step(actions).obs)
        all_actions.append(actions)
    return all_obs, all_actions


def options(**changes) -> AgentParams:
    """The variant options of ``changes``, the rest the paper's (code latents, spawn order)."""
    if "hidden_features" in changes:
        changes["maspm_hidden_features"] = changes.pop("hidden_features")
    return AgentParams(**{"decode_latents": False, "sort_humans": False, **changes})


def variant(name: str, **changes):
    vae, lstm = tiny_world_model()
    return make_variant(name, vae, lstm, options(**changes), obs_dim=OBS_DIM)


def latents(v, obs: np.ndarray) -> torch.Tensor:
    with torch.no_grad():
        return v.vae.encode(torch.as_tensor(obs))[0]


def lstm_step(v, z, actions, state):
    with torch.no_grad():
        predicted, (h, c) = v.lstm.step(z, torch.as_tensor(actions), state)
    return predicted, WorldModelState(h, c)


@pytest.mark.parametrize(
    ("name", "options", "size"),
    [
        ("dueling-dqn", {}, OBS_DIM),
        ("wm-dueling-dqn", {}, LATENT + HIDDEN),
        ("2stepahead", {}, LATENT + HIDDEN),
        ("maspm", {}, LATENT * 5),
        ("2stepahead-maspm", {}, LATENT * 5),
        ("2stepahead-maspm", {"hidden_features": True}, LATENT + 4 * HIDDEN),
    ],
)
def test_feature_sizes(name: str, options: dict, size: int) -> None:
    v = variant(name, **options)
    obs, actions = observations(2)
    assert v.feature_dim == size
    first = v.reset(obs[0])
    next_features, features = v.step(obs[1], actions[0])
    for f in (first, next_features, features):
        assert f.shape == (NUM_ENVS, size) and f.dtype == torch.float32
        assert not f.requires_grad
    assert all(not p.requires_grad for p in v.lstm.parameters()) if v.lstm else True


def test_paper_sizes_with_the_paper_world_model() -> None:
    from socnav_wm.worldmodel.lstm import LatentLSTM
    from socnav_wm.worldmodel.vae import VAE

    vae, lstm = VAE(23, 256, 16), LatentLSTM(16, 4, 256)
    sizes = {name: make_variant(name, vae, lstm, options()).feature_dim for name in VARIANTS}
    assert sizes == {
        "dueling-dqn": 23,
        "wm-dueling-dqn": 272,
        "2stepahead": 272,
        "maspm": 80,
        "2stepahead-maspm": 80,
    }
    assert (
        make_variant("2stepahead-maspm", vae, lstm, options(hidden_features=True)).feature_dim
        == 1040
    )
    decoded = {
        name: make_variant(name, vae, lstm, options(decode_latents=True)).feature_dim
        for name in VARIANTS
    }
    assert decoded == {
        "dueling-dqn": 23,
        "wm-dueling-dqn": 23 + 256,
        "2stepahead": 23 + 256,
        "maspm": 23 * 5,
        "2stepahead-maspm": 23 * 5,
    }


def test_dueling_dqn_features_are_the_observation() -> None:
    v = make_variant("dueling-dqn", options=options())
    obs, actions = observations(1)
    assert torch.equal(v.reset(obs[0]), torch.as_tensor(obs[0]))
    next_features, features = v.step(obs[1], actions[0])
    assert torch.equal(next_features, torch.as_tensor(obs[1]))
    assert torch.equal(features, next_features)


def test_world_model_features_are_z_and_the_updated_hidden_state() -> None:
    v = variant("wm-dueling-dqn")
    obs, actions = observations(3)
    features = v.reset(obs[0])
    # t = 0: the LSTM consumes (z_0, stop) from a zero state (the robot starts at rest).
    state = v.zero_state(NUM_ENVS)
    z = latents(v, obs[0])
    _, state = lstm_step(v, z, np.full(NUM_ENVS, STOP), state)
    torch.testing.assert_close(features, torch.cat([z, state.h], dim=1))
    for t in range(3):
        next_features, _ = v.step(obs[t + 1], actions[t])
        z = latents(v, obs[t + 1])
        _, state = lstm_step(v, z, actions[t], state)  # the action just taken
        torch.testing.assert_close(next_features, torch.cat([z, state.h], dim=1))
        torch.testing.assert_close(v.state.h, state.h)


@pytest.mark.parametrize("carry_imagined", [False, True])
def test_2stepahead_rolls_the_action_just_taken_twice(carry_imagined: bool) -> None:
    v = variant("2stepahead", carry_imagined=carry_imagined)
    obs, actions = observations(3)
    v.reset(obs[0])
    state = v.state
    for t in range(3):
        next_features, _ = v.step(obs[t + 1], actions[t])
        z = latents(v, obs[t + 1])
        predicted, real = lstm_step(v, z, actions[t], state)
        _, imagined = lstm_step(v, predicted, actions[t], real)  # from the predicted latent
        torch.testing.assert_close(next_features, torch.cat([z, imagined.h], dim=1))
        state = imagined if carry_imagined else real
        torch.testing.assert_close(v.state.h, state.h)
        torch.testing.assert_close(v.state.c, state.c)


def test_2stepahead_with_horizon_1_is_wm_dueling_dqn() -> None:
    obs, actions = observations(4)
    one = variant("2stepahead", horizon=1)
    wm = variant("wm-dueling-dqn")
    torch.testing.assert_close(one.reset(obs[0]), wm.reset(obs[0]))
    for t in range(4):
        torch.testing.assert_close(
            one.step(obs[t + 1], actions[t]), wm.step(obs[t + 1], actions[t])
        )


def test_2stepahead_horizon_k_takes_k_steps() -> None:
    v = variant("2stepahead", horizon=4)
    obs, actions = observations(1)
    v.reset(obs[0])
    state = v.state
    next_features, _ = v.step(obs[1], actions[0])
    z = latents(v, obs[1])
    predicted, real = lstm_step(v, z, actions[0], state)
    imagined = real
    for _ in range(3):
        predicted, imagined = lstm_step(v, predicted, actions[0], imagined)
    torch.testing.assert_close(next_features, torch.cat([z, imagined.h], dim=1))
    torch.testing.assert_close(v.state.h, real.h)


def test_maspm_slot_k_is_the_prediction_for_action_k_from_the_same_state() -> None:
    v = variant("maspm")
    obs, actions = observations(3)
    v.reset(obs[0])
    for t in range(3):
        before = v.state
        next_features, _ = v.step(obs[t + 1], actions[t])
        z = latents(v, obs[t + 1])
        torch.testing.assert_close(next_features[:, :LATENT], z)
        for k in range(4):
            predicted, _ = lstm_step(v, z, np.full(NUM_ENVS, k), before)
            slot = next_features[:, LATENT * (k + 1) : LATENT * (k + 2)]
            torch.testing.assert_close(slot, predicted)
        # The carried state is the taken action's step, not any imagined one.
        _, real = lstm_step(v, z, actions[t], before)
        torch.testing.assert_close(v.state.h, real.h)
        torch.testing.assert_close(v.state.c, real.c)
    # Slots differ between actions (the original `.all()` bug made most of them copies).
    slots = next_features[:, LATENT:].reshape(NUM_ENVS, 4, LATENT)
    assert not torch.allclose(slots[:, 0], slots[:, 1])


@pytest.mark.parametrize("hidden_features", [False, True])
def test_2stepahead_maspm_slot_k_is_two_steps_with_action_k(hidden_features: bool) -> None:
    v = variant("2stepahead-maspm", hidden_features=hidden_features)
    obs, actions = observations(2)
    v.reset(obs[0])
    for t in range(2):
        before = v.state
        next_features, _ = v.step(obs[t + 1], actions[t])
        z = latents(v, obs[t + 1])
        torch.testing.assert_close(next_features[:, :LATENT], z)
        width = HIDDEN if hidden_features else LATENT
        for k in range(4):
            repeated = np.full(NUM_ENVS, k)
            predicted, first = lstm_step(v, z, repeated, before)
            predicted, second = lstm_step(v, predicted, repeated, first)
            expected = second.h if hidden_features else predicted
            slot = next_features[:, LATENT + width * k : LATENT + width * (k + 1)]
            torch.testing.assert_close(slot, expected)
        _, real = lstm_step(v, z, actions[t], before)
        torch.testing.assert_close(v.state.h, real.h)


def test_2stepahead_maspm_with_horizon_1_is_maspm() -> None:
    obs, actions = observations(3)
    one = variant("2stepahead-maspm", horizon=1)
    maspm = variant("maspm")
    torch.testing.assert_close(one.reset(obs[0]), maspm.reset(obs[0]))
    for t in range(3):
        torch.testing.assert_close(
            one.step(obs[t + 1], actions[t]), maspm.step(obs[t + 1], actions[t])
        )


@pytest.mark.parametrize(
    ("name", "slots"),
    [("wm-dueling-dqn", 1), ("2stepahead", 1), ("maspm", 5), ("2stepahead-maspm", 5)],
)
def test_decode_latents_replaces_every_latent_by_its_decoding(name: str, slots: int) -> None:
    # The first `slots` blocks of a variant's features are latents (z, then the predictions);
    # decoded, each becomes the VAE's reconstruction in raw units, and the rest is unchanged.
    plain, decoded = variant(name), variant(name, decode_latents=True)
    assert decoded.feature_dim == plain.feature_dim + slots * (OBS_DIM - LATENT)
    obs, actions = observations(2)
    pairs = [(plain.reset(obs[0]), decoded.reset(obs[0]))]
    for t in range(2):
        pairs.append(
            (plain.step(obs[t + 1], actions[t])[0], decoded.step(obs[t + 1], actions[t])[0])
        )
    for codes, shown in pairs:
        blocks = codes[:, : LATENT * slots].reshape(NUM_ENVS, slots, LATENT)
        with torch.no_grad():
            expected = decoded.vae.destandardize(decoded.vae.decode(blocks)).flatten(1)
        torch.testing.assert_close(shown[:, : OBS_DIM * slots], expected)
        torch.testing.assert_close(shown[:, OBS_DIM * slots :], codes[:, LATENT * slots :])
    # Decoding changes what the Q-network sees, never the world model's state.
    torch.testing.assert_close(decoded.state.h, plain.state.h)
    torch.testing.assert_close(decoded.state.c, plain.state.c)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_reset_starts_only_the_reset_envs_afresh(name: str) -> None:
    obs, actions = observations(3)
    new_obs, _ = observations(0, seed=5)
    reset_mask = np.array([False, True, False, False, True])
    v, plain, fresh = variant(name), variant(name), variant(name)
    for model in (v, plain):
        model.reset(obs[0])
        model.step(obs[1], actions[0])
    next_features, features = v.step(obs[2], actions[1], reset_mask, new_obs[0][reset_mask])
    plain_next, plain_features = plain.step(obs[2], actions[1])
    first = fresh.reset(new_obs[0][reset_mask])
    # s′ of every env is the step's; the features to act on are the new episode's in reset envs.
    torch.testing.assert_close(next_features, plain_next)
    torch.testing.assert_close(features[~reset_mask], plain_features[~reset_mask])
    torch.testing.assert_close(features[reset_mask], first)
    # The state of the reset envs is a new episode's; the others' is the plain step's.
    torch.testing.assert_close(v.state.h[~reset_mask], plain.state.h[~reset_mask])
    torch.testing.assert_close(v.state.h[reset_mask], fresh.state.h)
    torch.testing.assert_close(v.state.c[reset_mask], fresh.state.c)
    # And the next step goes on from there, the same as a variant that only saw the new episode.
    next_features, _ = v.step(obs[3], actions[2])
    fresh_next, _ = fresh.step(obs[3][reset_mask], actions[2][reset_mask])
    torch.testing.assert_close(next_features[reset_mask], fresh_next)


def test_state_dict_round_trip() -> None:
    obs, actions = observations(2)
    v = variant("maspm")
    v.reset(obs[0])
    v.step(obs[1], actions[0])
    other = variant("maspm")
    other.load_state_dict(v.state_dict())
    torch.testing.assert_close(other.step(obs[2], actions[1]), v.step(obs[2], actions[1]))


def test_bad_names_and_options() -> None:
    with pytest.raises(ValueError) as error:
        make_variant("dqn")
    message = str(error.value)
    assert "\n" not in message
    assert message == (
        "variant: unknown 'dqn'; expected one of dueling-dqn, wm-dueling-dqn, 2stepahead, "
        "maspm, 2stepahead-maspm"
    )
    with pytest.raises(ValueError, match="'maspm' needs the VAE and the LSTM"):
        make_variant("maspm")
    with pytest.raises(ValueError, match="agent.horizon: must be > 0"):
        variant("2stepahead", horizon=0)
    vae, lstm = tiny_world_model()
    with pytest.raises(ValueError, match="reads 23-d observations"):
        make_variant("maspm", vae, lstm, options(), obs_dim=9)
    with pytest.raises(RuntimeError, match="reset"):
        make_variant("dueling-dqn", options=options()).step(
            np.zeros((1, 23), np.float32), np.zeros(1, np.int64)
        )


def test_sort_humans_by_distance_by_hand() -> None:
    goal = [1.0, 2.0]
    far = [3.0, 4.0, 0.1, 0.2, 0.36, 0.3, 0.5]  # 5 m away
    near = [0.0, 1.0, 0.3, 0.4, 0.36, 0.1, 0.5]  # 1 m
    middle = [-2.0, 0.0, 0.5, 0.6, 0.36, 0.2, 0.5]  # 2 m
    obs = torch.tensor([goal + far + near + middle])
    expected = torch.tensor([goal + near + middle + far])
    assert torch.equal(sort_humans_by_distance(obs), expected)
    # Any spawn order of the same people gives the same input.
    shuffled = torch.tensor([goal + middle + far + near])
    assert torch.equal(sort_humans_by_distance(shuffled), expected)
    # Ties keep spawn order; fewer than two humans: nothing to sort.
    tie = torch.tensor([goal + near + [1.0, 0.0, 9, 9, 9, 9, 9]])
    assert torch.equal(sort_humans_by_distance(tie), tie)
    assert torch.equal(
        sort_humans_by_distance(torch.tensor([goal + far])), torch.tensor([goal + far])
    )


@pytest.mark.parametrize("name", ["dueling-dqn", "maspm"])
def test_sort_humans_option_feeds_the_sorted_observation(name: str) -> None:
    obs, actions = observations(1)
    sorted_obs = sort_humans_by_distance(torch.as_tensor(obs[1]))
    assert not torch.equal(sorted_obs, torch.as_tensor(obs[1]))  # some env is out of order
    v, plain = variant(name, sort_humans=True), variant(name)
    v.reset(obs[0])
    plain.reset(sort_humans_by_distance(torch.as_tensor(obs[0])))
    torch.testing.assert_close(v.step(obs[1], actions[0]), plain.step(sorted_obs, actions[0]))
