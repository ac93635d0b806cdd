"""The DQN learner's update, hyper-parameters, the training loop on the real simulator
(learning, determinism, resume), agent files and greedy episodes."""

import copy
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from socnav_wm.agents.agent_file import (
    AgentFileError,
    agent_from_result,
    greedy_episodes,
    load_agent,
    save_agent,
)
from socnav_wm.agents.learner import DQNLearner, double_dqn_targets
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import Batch
from socnav_wm.agents.training import EPISODE_COLUMNS, selection_seed, train_agent
from socnav_wm.config import load_params
from socnav_wm.env import EnvParams
from socnav_wm.metrics import episodes_to_solve
from socnav_wm.worldmodel.files import save_vae
from tests.agents.conftest import tiny_world_model

# A small empty room: the robot only has to turn towards the goal and drive there.
EASY_ENV = EnvParams(num_humans=0, room_size=4.0, max_steps=50)
# Tiny runs for the loop's bookkeeping (determinism, resume, files): seconds, not minutes.
TINY = AgentParams(
    episodes=40,
    num_envs=4,
    batch_size=16,
    buffer_size=2_000,
    learning_starts=32,
    updates_per_step=2,
    trunk_sizes=(32,),
    stream_size=16,
    epsilon_decay=0.95,
    checkpoint_every=10,
    select_every=0,
    device="cpu",
)
TINY_ENV = EnvParams(room_size=6.0, max_steps=30)


def weights(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in module.state_dict().items()}


def assert_same_weights(a: torch.nn.Module, b: torch.nn.Module) -> None:
    wa, wb = weights(a), weights(b)
    assert wa.keys() == wb.keys()
    for key in wa:
        assert torch.equal(wa[key], wb[key]), key


def without_time(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in row.items() if k != "wall_time"} for row in rows]


# --- the update rule --------------------------------------------------------------------------


def test_double_dqn_target_by_hand() -> None:
    rewards = torch.tensor([1.0, -1.0, 0.5])
    terminals = torch.tensor([0.0, 1.0, 0.0])
    # The online network picks the action at s′ (argmax 2, 0, 1); the target network values it.
    next_online = torch.tensor([[0.0, 1.0, 3.0, 2.0], [9.0, 0.0, 0.0, 0.0], [0.0, 5.0, 1.0, 0.0]])
    next_target = torch.tensor([[7.0, 7.0, 2.0, 9.0], [4.0, 4.0, 4.0, 4.0], [8.0, -2.0, 8.0, 8.0]])
    y = double_dqn_targets(rewards, terminals, next_online, next_target, 0.9)
    # 1 + 0.9·2 = 2.8; terminal: −1; 0.5 + 0.9·(−2) = −1.3 (not max target 8: no over-estimate).
    torch.testing.assert_close(y, torch.tensor([2.8, -1.0, -1.3]))
    # n-step transitions carry their own discount γᵏ.
    y = double_dqn_targets(
        rewards, terminals, next_online, next_target, torch.tensor([0.5, 1, 0.25])
    )
    torch.testing.assert_close(y, torch.tensor([2.0, -1.0, 0.0]))


def test_one_update_takes_a_gradient_step_and_a_polyak_step() -> None:
    torch.manual_seed(0)
    params = TINY.replace(polyak=0.75, grad_clip=0.0, learning_rate=1e-2)
    learner = DQNLearner(3, params, torch.device("cpu"))
    # Make the target differ from the online network so the averaging is visible.
    with torch.no_grad():
        for p in learner.target_network.parameters():
            p.add_(1.0)
    online_before = weights(learner.q_network)
    target_before = weights(learner.target_network)
    batch = Batch(
        torch.randn(8, 3), torch.randint(0, 4, (8,)), torch.randn(8), torch.randn(8, 3),
        torch.zeros(8), torch.full((8,), 0.9),
    )  # fmt: skip
    loss = learner.update(batch)
    assert loss.ndim == 0 and loss > 0
    online_after = weights(learner.q_network)
    target_after = weights(learner.target_network)
    assert any(not torch.equal(online_before[k], online_after[k]) for k in online_before)
    for key in target_before:
        expected = 0.75 * target_before[key] + 0.25 * online_after[key]
        torch.testing.assert_close(target_after[key], expected)


@pytest.mark.parametrize(
    ("optimizer", "grad_clip", "huber"),
    [("adam", 0.05, False), ("adamw", 0.0, True), ("adam", 100.0, False)],
)
def test_update_matches_the_textbook_update(optimizer: str, grad_clip: float, huber: bool) -> None:
    """Five updates give what a separate network with Adam, clip_grad_norm_ and Polyak
    averaging written out step by step gives (the learner's options reach its update)."""
    torch.manual_seed(0)
    params = TINY.replace(optimizer=optimizer, grad_clip=grad_clip, huber=huber, weight_decay=0.01,
        learning_rate=1e-2,
    )  # fmt: skip
    learner = DQNLearner(5, params, torch.device("cpu"))
    online = copy.deepcopy(learner.q_network)  # ordinary, separate parameters
    target = copy.deepcopy(learner.target_network)
    kind = torch.optim.AdamW if optimizer == "adamw" else torch.optim.Adam
    reference = kind(online.parameters(), lr=1e-2, weight_decay=0.01)
    clipped = False
    for _ in range(5):
        batch = Batch(
            torch.randn(16, 5), torch.randint(0, 4, (16,)), torch.randn(16), torch.randn(16, 5),
            (torch.rand(16) < 0.2).float(), torch.full((16,), 0.95),
        )  # fmt: skip
        learner.update(batch)
        with torch.no_grad():
            y = double_dqn_targets(
                batch.rewards, batch.terminals, online(batch.next_features),
                target(batch.next_features), batch.discounts,
            )  # fmt: skip
        q = online(batch.features).gather(1, batch.actions.unsqueeze(1)).squeeze(1)
        reference.zero_grad()
        (F.smooth_l1_loss(q, y) if huber else F.mse_loss(q, y)).backward()
        if grad_clip > 0:
            norm = torch.nn.utils.clip_grad_norm_(online.parameters(), grad_clip)
            clipped |= bool(norm > grad_clip)
        reference.step()
        with torch.no_grad():
            for t, o in zip(target.parameters(), online.parameters(), strict=True):
                t.mul_(params.polyak).add_(o, alpha=1 - params.polyak)
    assert clipped == (grad_clip == 0.05)  # the small clip did bite, the large one did not
    for mine, theirs in ((learner.q_network, online), (learner.target_network, target)):
        for key, value in theirs.state_dict().items():
            torch.testing.assert_close(mine.state_dict()[key], value, rtol=1e-4, atol=1e-6)


def test_episodes_to_solve_by_hand() -> None:
    success = [0, 1, 1, 0, 1, 1, 1, 1]
    # Windows of 4: [0,1,1,0] .5, [1,1,0,1] .75 (ends at episode 5), …
    assert episodes_to_solve(success, window=4, rate=0.75) == 5
    assert episodes_to_solve(success, window=4, rate=1.0) == 8
    assert episodes_to_solve(success, window=4, rate=0.8) == 8
    assert episodes_to_solve(success, window=2, rate=1.0) == 3
    assert episodes_to_solve(success[:3], window=4, rate=0.1) is None  # not a full window


# --- hyper-parameters ---------------------------------------------------------------------------


def test_default_params_are_one_shared_set() -> None:
    params = AgentParams()
    for variant in ("dueling-dqn", "maspm", "2stepahead"):
        assert params.resolved(variant) is params
    assert params.bootstrap_truncation is True
    assert params.trunk_sizes == (512, 128)


def test_paper_overlay_reproduces_the_per_variant_table() -> None:
    paper = load_params("params.yaml", ["agent.episodes=10"], ["configs/paper.yaml"]).agent
    vanilla = paper.resolved("dueling-dqn")
    assert (vanilla.gamma, vanilla.buffer_size, vanilla.polyak) == (0.99, 200_000, 0.995)
    assert (vanilla.optimizer, vanilla.learning_rate, vanilla.grad_clip) == ("adam", 1e-4, 0.5)
    assert (vanilla.epsilon_decay, vanilla.epsilon_min) == (0.995, 0.01)
    wm = paper.resolved("wm-dueling-dqn")
    assert (wm.optimizer, wm.amsgrad) == ("adamw", True)
    step = paper.resolved("2stepahead")
    assert (step.epsilon_decay, step.epsilon_min, step.optimizer) == (0.9995, 0.1, "adamw")
    for name in ("maspm", "2stepahead-maspm"):
        maspm = paper.resolved(name)
        assert (maspm.gamma, maspm.buffer_size, maspm.polyak) == (0.98, 1_000_000, 0.99)
        assert (maspm.epsilon_decay, maspm.optimizer) == (0.998, "adam")
    assert paper.resolved("maspm").episodes == 10  # run scale is not part of the preset
    for name in ("maspm", "2stepahead"):  # the paper's reward and observation order
        assert (paper.resolved(name).progress_reward, paper.resolved(name).sort_humans) == (
            0,
            False,
        )


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"gamma": 1.5}, "agent.gamma: must be in [0, 1], got 1.5"),
        ({"episodes": 0}, "agent.episodes: must be > 0, got 0"),
        ({"episodes": 2.5}, "agent.episodes: expected an integer, got 2.5"),
        ({"num_envs": True}, "agent.num_envs: expected an integer, got True"),
        ({"huber": "yes"}, "agent.huber: expected true or false, got 'yes'"),
        ({"polyak": 1.0}, "agent.polyak: must be in [0, 1), got 1.0"),
        ({"learning_rate": float("nan")}, "agent.learning_rate: must be finite, got nan"),
        ({"optimizer": "sgd"}, "agent.optimizer: must be one of adam, adamw, got 'sgd'"),
        ({"device": "tpu"}, "agent.device: must be one of auto, cpu, cuda, got 'tpu'"),
        ({"epsilon_min": 0.5, "epsilon_start": 0.1}, "agent.epsilon_min: must be <= epsilon_st"),
        ({"buffer_size": 10}, "agent.buffer_size: must be >= batch_size (128), got 10"),
        ({"learning_starts": 8}, "agent.learning_starts: must be between batch_size (128)"),
        ({"trunk_sizes": ()}, "agent.trunk_sizes: expected a non-empty list of positive"),
        ({"trunk_sizes": (64, 0)}, "agent.trunk_sizes: expected a non-empty list of positive"),
        ({"horizon": 0}, "agent.horizon: must be > 0, got 0"),
        ({"progress_reward": -1.0}, "agent.progress_reward: must be >= 0, got -1.0"),
        ({"select_every": -1}, "agent.select_every: must be >= 0, got -1"),
        ({"select_episodes": 0}, "agent.select_episodes: must be > 0, got 0"),
    ],
)
def test_bad_params_give_one_line_errors(values: dict, message: str) -> None:
    with pytest.raises(ValueError) as error:
        AgentParams(**values)
    assert str(error.value).startswith(message)
    assert "\n" not in str(error.value)


def test_params_from_dict_names_unknown_keys_and_lists_become_tuples() -> None:
    with pytest.raises(ValueError, match="agent: unknown option"):
        AgentParams.from_dict({"gama": 0.9})
    params = AgentParams.from_dict({"trunk_sizes": [128, 128]})
    assert params.trunk_sizes == (128, 128)
    assert AgentParams.from_dict(params.to_dict()) == params


# --- training -----------------------------------------------------------------------------------


def test_learns_an_easy_navigation_task_quickly() -> None:
    params = AgentParams(
        episodes=250,
        num_envs=16,
        batch_size=64,
        buffer_size=20_000,
        learning_starts=256,
        updates_per_step=8,
        learning_rate=1e-3,
        gamma=0.9,
        progress_reward=1.0,
        epsilon_decay=0.98,
        trunk_sizes=(64,),
        stream_size=32,
        checkpoint_every=1_000,
        device="cpu",
    )
    result = train_agent("dueling-dqn", params, EASY_ENV, None, None, seed=0)
    early = np.mean([row["success"] for row in result.episodes[:50]])
    runs = greedy_episodes(
        agent_from_result(result), EASY_ENV, seed=10_000, scenario_ids=np.arange(200)
    )
    greedy = np.mean([run.success for run in runs])
    assert early < 0.6  # mostly random at first
    assert greedy >= 0.85, greedy


def test_training_log_rows() -> None:
    seen: list[dict] = []
    result = train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=1, on_episodes=seen.extend)
    rows = result.episodes
    assert len(rows) == TINY.episodes and seen == rows
    assert [row["episode"] for row in rows] == list(range(1, TINY.episodes + 1))
    assert set(rows[0]) == set(EPISODE_COLUMNS)
    for row in rows:
        outcome = row["success"] + row["collision"] + row["timeout"]
        assert outcome == 1  # exactly one way to end
        assert row["collision"] == row["human_collision"] or row["wall_collision"]
        assert 1 <= row["length"] <= TINY_ENV.max_steps
        assert not row["timeout"] or row["length"] == TINY_ENV.max_steps
        assert row["return"] == pytest.approx(-1.0) or row["success"]  # the paper's reward
    assert np.all(np.diff([row["env_steps"] for row in rows]) >= 0)
    assert np.all(np.diff([row["epsilon"] for row in rows]) <= 0)
    assert rows[0]["epsilon"] == 1.0 and rows[-1]["epsilon"] < 0.5
    assert len({row["scenario_id"] for row in rows}) == len(rows)  # every episode a new scenario
    assert result.env_steps == rows[-1]["env_steps"] and result.updates > 0


@pytest.mark.parametrize("variant", ["dueling-dqn", "2stepahead-maspm"])
def test_same_seed_same_weights(variant: str, world_model_files: tuple[Path, Path]) -> None:
    runs = [
        train_agent(variant, TINY, TINY_ENV, *world_model_files, seed=seed) for seed in (3, 3, 4)
    ]
    assert_same_weights(runs[0].q_network, runs[1].q_network)
    assert without_time(runs[0].episodes) == without_time(runs[1].episodes)
    assert not torch.equal(runs[0].q_network.trunk[0].weight, runs[2].q_network.trunk[0].weight)


def test_model_selection_keeps_the_best_greedy_weights() -> None:
    final = train_agent("dueling-dqn", TINY, EASY_ENV, None, None, seed=2)
    params = TINY.replace(select_every=10, select_episodes=20)
    result = train_agent("dueling-dqn", params, EASY_ENV, None, None, seed=2)
    # The greedy runs use their own simulator and generators: the training is the same.
    assert without_time(result.episodes) == without_time(final.episodes)
    episodes = [run["episode"] for run in result.selection]
    assert episodes[-1] == TINY.episodes
    for k, episode in enumerate(episodes[:-1], start=1):  # episodes end num_envs at a time
        assert 10 * k <= episode < 10 * k + TINY.num_envs
    rates = [run["success_rate"] for run in result.selection]
    best = max(rates)
    assert result.selected_episode == max(
        run["episode"] for run in result.selection if run["success_rate"] == best
    )  # ties go to the later weights
    # This seed's best run is not the last one, so the kept weights are not the final ones.
    assert result.selected_episode < TINY.episodes
    assert not torch.equal(result.q_network.trunk[0].weight, final.q_network.trunk[0].weight)
    # The kept weights are those that scored best: running them again gives that rate.
    runs = greedy_episodes(
        agent_from_result(result), EASY_ENV, seed=selection_seed(2), scenario_ids=np.arange(20)
    )
    assert np.mean([run.success for run in runs]) == best
    assert final.selection == [] and final.selected_episode is None


class Interrupted(Exception):
    pass


@pytest.mark.parametrize(
    ("variant", "n_step", "select_every"),
    [("dueling-dqn", 1, 0), ("2stepahead", 3, 0), ("dueling-dqn", 1, 10)],
)
def test_resumed_run_ends_with_the_same_weights(
    variant: str,
    n_step: int,
    select_every: int,
    world_model_files: tuple[Path, Path],
    tmp_path: Path,
) -> None:
    files = world_model_files
    params = TINY.replace(n_step=n_step, select_every=select_every, select_episodes=20)
    uninterrupted = train_agent(variant, params, TINY_ENV, *files, seed=5)

    def interrupt(rows: list[dict]) -> None:
        if rows[-1]["episode"] >= 25:  # after the checkpoint at 20, before the one at 30
            raise Interrupted

    checkpoint = tmp_path / "run.ckpt"
    with pytest.raises(Interrupted):
        train_agent(variant, params, TINY_ENV, *files, seed=5, checkpoint_path=checkpoint,
                    on_episodes=interrupt)  # fmt: skip
    saved = torch.load(checkpoint, weights_only=True)["state"]
    assert 20 <= len(saved["rows"]) < 25
    resumed = train_agent(
        variant, params, TINY_ENV, *files, seed=5, checkpoint_path=checkpoint, resume=True
    )
    assert_same_weights(uninterrupted.q_network, resumed.q_network)
    assert without_time(resumed.episodes) == without_time(uninterrupted.episodes)
    assert (resumed.env_steps, resumed.updates) == (uninterrupted.env_steps, uninterrupted.updates)
    assert resumed.selection == uninterrupted.selection
    assert resumed.selected_episode == uninterrupted.selected_episode
    assert [p.name for p in tmp_path.iterdir()] == ["run.ckpt"]  # no temporary files left
    # Resuming a finished run just gives its result back.
    again = train_agent(
        variant, params, TINY_ENV, *files, seed=5, checkpoint_path=checkpoint, resume=True
    )
    assert_same_weights(again.q_network, resumed.q_network)


def test_resume_refuses_another_runs_checkpoint(tmp_path: Path) -> None:
    checkpoint = tmp_path / "run.ckpt"
    train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=0, checkpoint_path=checkpoint)
    other = TINY.replace(gamma=0.9)
    with pytest.raises(ValueError) as error:
        train_agent("dueling-dqn", other, TINY_ENV, None, None, seed=0,
                    checkpoint_path=checkpoint, resume=True)  # fmt: skip
    assert str(error.value) == (
        f"{checkpoint}: checkpoint of a different run (params.gamma differs); "
        "delete it or train without --resume"
    )


def test_an_unreadable_checkpoint_is_set_aside_and_training_starts_afresh(tmp_path: Path) -> None:
    """A damaged checkpoint must not block every later `dvc repro` (which passes --resume)."""
    fresh = train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=0)
    checkpoint = tmp_path / "run.ckpt"
    checkpoint.write_bytes(b"not a checkpoint")
    with pytest.warns(UserWarning, match="not a readable agent checkpoint.*moved to"):
        resumed = train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=0,
                              checkpoint_path=checkpoint, resume=True)  # fmt: skip
    assert_same_weights(resumed.q_network, fresh.q_network)
    assert (tmp_path / "run.ckpt.unreadable-0").read_bytes() == b"not a checkpoint"


@pytest.mark.parametrize("bootstrap", [True, False])
def test_time_limit_truncation_is_bootstrapped_by_default(bootstrap: bool, tmp_path: Path) -> None:
    # Three steps in a big empty room: every episode times out, none terminates.
    env = EnvParams(num_humans=0, max_steps=3, min_goal_distance=3.0)
    params = TINY.replace(episodes=8, bootstrap_truncation=bootstrap)
    checkpoint = tmp_path / "run.ckpt"
    result = train_agent("dueling-dqn", params, env, None, None, seed=0, checkpoint_path=checkpoint)
    assert all(row["timeout"] for row in result.episodes)
    terminals = torch.load(checkpoint, weights_only=True)["state"]["replay"]["terminals"]
    # Every third transition ends an episode: terminal only when timeouts count as terminal.
    assert terminals.sum().item() == (0 if bootstrap else terminals.numel() // 3)


def test_progress_reward_is_added_for_learning_only(tmp_path: Path) -> None:
    # No humans (no discomfort) and 3-step episodes that all time out: the env pays 0, 0, −1.
    env = EnvParams(num_humans=0, max_steps=3, min_goal_distance=3.0)
    params = TINY.replace(episodes=8, progress_reward=2.0)
    checkpoint = tmp_path / "run.ckpt"
    result = train_agent("dueling-dqn", params, env, None, None, seed=0, checkpoint_path=checkpoint)
    assert all(row["return"] == -1.0 for row in result.episodes)  # logged: the env's return
    replay = torch.load(checkpoint, weights_only=True)["state"]["replay"]
    # dueling-dqn's features are the observation, which starts with the goal in the robot frame.
    progress = replay["features"][:, :2].norm(dim=1) - replay["next_features"][:, :2].norm(dim=1)
    vector_step = torch.arange(replay["rewards"].numel()) // params.num_envs
    env_reward = torch.where(vector_step % 3 == 2, -1.0, 0.0)
    torch.testing.assert_close(replay["rewards"], env_reward + 2.0 * progress)
    assert progress.abs().max() > 0.1  # the robot did move


def test_train_agent_errors(world_model_files: tuple[Path, Path]) -> None:
    with pytest.raises(ValueError, match="variant: unknown 'vanilla'; expected one of"):
        train_agent("vanilla", TINY, TINY_ENV, None, None, seed=0)
    with pytest.raises(ValueError, match="'maspm' needs the VAE and LSTM files"):
        train_agent("maspm", TINY, TINY_ENV, None, None, seed=0)
    with pytest.raises(ValueError, match="seed: expected a non-negative integer"):
        train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=-1)
    vae_path, _ = world_model_files
    with pytest.raises(ValueError, match="holds a 'vae' model, expected a 'lstm' model"):
        train_agent("maspm", TINY, TINY_ENV, vae_path, vae_path, seed=0)


# --- agent files and evaluation -----------------------------------------------------------------


@pytest.mark.parametrize("decode_latents", [False, True])
def test_save_load_agent_and_evaluate(
    world_model_files: tuple[Path, Path], tmp_path: Path, decode_latents: bool
) -> None:
    params = TINY.replace(decode_latents=decode_latents)
    result = train_agent("maspm", params, TINY_ENV, *world_model_files, seed=2)
    path = tmp_path / "agents" / "maspm" / "seed-2.pt"
    save_agent(path, result, extra={"note": "test"})
    agent = load_agent(path, device="cpu")
    assert agent.variant_name == "maspm" and agent.params == result.params
    assert agent.extra["seed"] == 2 and agent.extra["note"] == "test"
    assert agent.variant.options.sort_humans is result.params.sort_humans is True
    # The file brings back the input the Q-network was trained on: z and 4 predictions, each
    # the code or, decoded, a 23-d observation.
    assert agent.variant.options.decode_latents is decode_latents
    slot = 23 if decode_latents else agent.variant.latent_dim
    assert agent.q_network.input_dim == agent.variant.feature_dim == 5 * slot
    assert_same_weights(agent.q_network, result.q_network)
    assert_same_weights(agent.variant.lstm, result.lstm)
    ids = np.arange(7, 19)
    runs = greedy_episodes(agent, TINY_ENV, seed=99, scenario_ids=ids, batch_size=5)
    assert [run.scenario_id for run in runs] == ids.tolist()
    for run in runs:
        assert run.success + (run.collision is not None) + run.truncated == 1
    # The file alone reproduces the in-memory agent's greedy behaviour, whatever the batch.
    direct = greedy_episodes(agent_from_result(result), TINY_ENV, seed=99, scenario_ids=ids)
    assert [r.actions.tolist() for r in runs] == [r.actions.tolist() for r in direct]
    features = agent.variant.reset(np.zeros((3, 23), np.float32))
    assert agent.act(features).shape == (3,)


def test_load_agent_errors(tmp_path: Path) -> None:
    with pytest.raises(AgentFileError, match="no such agent file"):
        load_agent(tmp_path / "missing.pt")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00\x01 garbage")
    with pytest.raises(AgentFileError, match="not a readable agent file"):
        load_agent(garbage)
    vae_file = tmp_path / "vae.pt"
    save_vae(vae_file, tiny_world_model()[0])
    with pytest.raises(AgentFileError) as error:
        load_agent(vae_file)
    assert str(error.value) == f"{vae_file}: not a socnav-wm agent file"
