"""params.yaml loading: defaults, overrides, one-line errors, round trip."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

from pipeline.config import (
    ConfigError,
    Params,
    flatten,
    load_params,
    params_dict,
    save_resolved,
)
from pipeline.env.params import EnvParams


def write(tmp_path: Path, text: str, name: str = "params.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def error_of(path: Path, overrides: tuple[str, ...] = ()) -> str:
    with pytest.raises(ConfigError) as info:
        load_params(path, overrides)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- defaults and the shipped style ------------------------------------------------------------


def test_empty_file_gives_every_default(tmp_path: Path) -> None:
    params = load_params(write(tmp_path, ""))
    assert params == Params()
    assert params.seed == 0
    assert params.env == EnvParams()
    assert (params.collect.episodes, params.collect.num_envs) == (4000, 512)
    assert params.collect.max_rows_per_shard == 400_000
    assert (params.vae.latent_dim, params.vae.hidden_dim, params.vae.kl_weight) == (16, 256, 1.0)
    assert (params.vae.batch_size, params.vae.val_fraction, params.vae.device) == (
        512,
        0.05,
        "auto",
    )
    assert (params.lstm.seq_len, params.lstm.batch_size, params.lstm.patience) == (16, 256, 5)


def test_shipped_style_file_with_partial_sections(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        # The pipeline's configuration.
        seed: 7
        env:
          human_policy: sfm
          max_steps: 101
        collect:
          episodes: 200
        vae:
          learning_rate: 1e-3   # YAML 1.1 would read this as a string
          kl_weight: 0.5
        lstm:                   # all defaults
        """,
    )
    params = load_params(path)
    assert params.seed == 7
    assert params.env.human_policy == "sfm" and params.env.max_steps == 101
    assert params.env.num_humans == 3  # untouched env keys keep the paper's values
    assert params.collect.episodes == 200 and params.collect.num_envs == 512
    assert params.vae.learning_rate == pytest.approx(1e-3)
    assert isinstance(params.vae.learning_rate, float)
    assert params.vae.kl_weight == 0.5
    assert params.lstm == Params().lstm


def test_fields_are_documented() -> None:
    for section in ("collect", "vae", "lstm"):
        model = type(getattr(Params(), section))
        for name, field in model.model_fields.items():
            assert field.description, f"{section}.{name} has no docstring"
    for name, field in Params.model_fields.items():
        assert field.description, name


def test_params_are_immutable() -> None:
    params = Params()
    with pytest.raises(ValueError):
        params.vae.batch_size = 3  # type: ignore[misc]


# --- overrides ---------------------------------------------------------------------------------


def test_overrides_of_every_type(tmp_path: Path) -> None:
    path = write(tmp_path, "vae:\n  kl_weight: 1.0\n")
    params = load_params(
        path,
        [
            "seed=3",
            "vae.kl_weight=0.5",
            "vae.learning_rate=3e-4",
            "vae.device=cpu",
            "env.human_policy=sfm",
            "env.orca_avoid_robot=true",
            "env.num_humans=5",
            "collect.episodes=10",
            "lstm.seq_len=4",
        ],
    )
    assert params.seed == 3
    assert params.vae.kl_weight == 0.5
    assert params.vae.learning_rate == pytest.approx(3e-4)
    assert params.vae.device == "cpu"
    assert params.env.human_policy == "sfm"
    assert params.env.orca_avoid_robot is True
    assert params.env.num_humans == 5
    assert params.collect.episodes == 10
    assert params.lstm.seq_len == 4


def test_override_creates_missing_section_and_wins_over_file(tmp_path: Path) -> None:
    path = write(tmp_path, "seed: 1\ncollect:\n  episodes: 100\n")
    params = load_params(path, ["collect.episodes=5", "lstm.hidden_dim=32", "seed=2"])
    assert (params.collect.episodes, params.lstm.hidden_dim, params.seed) == (5, 32, 2)


def test_int_accepted_where_float_expected(tmp_path: Path) -> None:
    params = load_params(write(tmp_path, "vae:\n  kl_weight: 2\nenv:\n  room_size: 12\n"))
    assert params.vae.kl_weight == 2.0
    assert params.env.room_size == 12


# --- errors: one line naming the source and the key ---------------------------------------------


def test_out_of_range_value(tmp_path: Path) -> None:
    message = error_of(write(tmp_path, "vae:\n  batch_size: -3\n"))
    assert message == (
        f"{tmp_path / 'params.yaml'}: vae.batch_size: Input should be greater than 0 (got -3)"
    )


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("vae:\n  val_fraction: 0.8\n", "vae.val_fraction: Input should be less than or equal"),
        ("vae:\n  kl_weight: -0.1\n", "vae.kl_weight: Input should be greater than or equal to 0"),
        ("vae:\n  learning_rate: .inf\n", "vae.learning_rate: Input should be a finite number"),
        ("lstm:\n  seq_len: 1\n", "lstm.seq_len: Input should be greater than or equal to 2"),
        ("collect:\n  episodes: 0\n", "collect.episodes: Input should be greater than 0"),
        ("seed: -1\n", "seed: Input should be greater than or equal to 0"),
        ("seed: true\n", "seed: Input should be a valid integer (got True)"),
        ("vae:\n  batch_size: 512.0\n", "vae.batch_size: Input should be a valid integer"),
        ("vae:\n  device: tpu\n", "vae.device: must be one of auto, cpu, cuda, got 'tpu'"),
        ("env:\n  human_policy: bogus\n", "env.human_policy: must be one of mixed, sfm, orca"),
        ("env:\n  room_size: -1\n", "env.room_size: must be > 0"),
        ("env:\n  num_humans: true\n", "env.num_humans: expected an integer, got True"),
        ("env:\n  orca_avoid_robot: 'no'\n", "env.orca_avoid_robot: expected true or false"),
        ("env: 3\n", "env: expected a mapping of keys, got 3"),
        ("vae: [1, 2]\n", "vae: expected a mapping of keys, got [1, 2]"),
    ],
)
def test_bad_values_name_the_key(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    message = error_of(path)
    assert message.startswith(f"{path}: {expected}"), message


def test_env_literal_message_matches_the_simulator(tmp_path: Path) -> None:
    message = error_of(write(tmp_path, "env:\n  human_policy: bogus\n"))
    assert message.endswith("env.human_policy: must be one of mixed, sfm, orca, got 'bogus'")


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("vae:\n  bacth_size: 3\n", "'vae.bacth_size' (did you mean 'vae.batch_size'?)"),
        ("env:\n  num_human: 3\n", "'env.num_human' (did you mean 'env.num_humans'?)"),
        ("dqn:\n  gamma: 0.9\n", "'dqn'"),
        ("seeed: 3\n", "'seeed' (did you mean 'seed'?)"),
        ("lstm:\n  zzz: 1\n", "'lstm.zzz'"),
    ],
)
def test_unknown_keys(tmp_path: Path, text: str, key: str) -> None:
    path = write(tmp_path, text)
    assert error_of(path) == f"{path}: unknown key {key}"


def test_several_errors_report_the_first_and_count_the_rest(tmp_path: Path) -> None:
    path = write(tmp_path, "vae:\n  batch_size: -3\n  max_epochs: 0\n  patience: 0\n")
    message = error_of(path)
    assert message.startswith(f"{path}: vae.batch_size: ")
    assert message.endswith("(and 2 more errors)")


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    assert error_of(path) == f"{path}: file not found"


def test_invalid_yaml_names_the_line(tmp_path: Path) -> None:
    path = write(tmp_path, "seed: 1\nvae:\n  batch_size: [1, 2\n  kl_weight: 1\n")
    message = error_of(path)
    assert message.startswith(f"{path}: not valid YAML (line ")


def test_invalid_yaml_line_number(tmp_path: Path) -> None:
    path = write(tmp_path, "seed: 1\nvae:\n  batch_size: 3: 4\n")
    assert error_of(path).startswith(f"{path}: not valid YAML (line 3, column")


def test_duplicate_key_is_an_error(tmp_path: Path) -> None:
    path = write(tmp_path, "vae:\n  batch_size: 3\n  batch_size: 4\n")
    message = error_of(path)
    assert message.startswith(f"{path}: not valid YAML (line 3, ")
    assert "duplicate key 'batch_size'" in message


def test_top_level_must_be_a_mapping(tmp_path: Path) -> None:
    path = write(tmp_path, "- 1\n- 2\n")
    assert error_of(path) == f"{path}: expected a mapping of sections, got list"


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("vae.x=1", "--set vae.x=1: unknown key 'vae.x'"),
        ("foo", "--set foo: expected section.key=value"),
        ("=3", "--set =3: expected section.key=value"),
        ("vae.=3", "--set vae.=3: expected section.key=value"),
        ("nope.x=1", "--set nope.x=1: unknown key 'nope.x'"),
        ("vae.latent_dim.x=1", "--set vae.latent_dim.x=1: unknown key 'vae.latent_dim.x'"),
        ("vae=3", "--set vae=3: 'vae' is a section; use vae.key=value"),
        ("seed.x=3", "--set seed.x=3: unknown key 'seed.x'"),
        ("vae.batch_size=-3", "--set vae.batch_size=-3: vae.batch_size: Input should be greater"),
        ("env.room_size=-1", "--set env.room_size=-1: env.room_size: must be > 0"),
        ("env.human_policy=x", "--set env.human_policy=x: env.human_policy: must be one of"),
        ("vae.batch_size=[1", "--set vae.batch_size=[1: not valid YAML ("),
        (  # an error inside the value still names the --set that wrote the whole value
            "agent.trunk_sizes=[512,abc]",
            "--set agent.trunk_sizes=[512,abc]: agent.trunk_sizes.1: Input should be a valid "
            "integer",
        ),
    ],
)
def test_override_errors_name_the_override(tmp_path: Path, override: str, expected: str) -> None:
    message = error_of(write(tmp_path, ""), (override,))
    assert message.startswith(expected), message


def test_bad_value_in_file_still_names_the_file_when_other_keys_are_overridden(
    tmp_path: Path,
) -> None:
    path = write(tmp_path, "vae:\n  batch_size: -3\n")
    assert error_of(path, ("vae.kl_weight=0.5",)).startswith(f"{path}: vae.batch_size: ")
    path = write(tmp_path, "agent:\n  trunk_sizes: [5, x]\n")
    assert error_of(path, ("agent.gamma=0.9",)).startswith(f"{path}: agent.trunk_sizes.1: ")


# --- output ------------------------------------------------------------------------------------


def test_save_resolved_round_trip(tmp_path: Path) -> None:
    params = load_params(
        write(tmp_path, "seed: 5\nenv:\n  human_policy: orca\n"),
        ["vae.kl_weight=0.25", "vae.learning_rate=1e-5", "lstm.device=cpu"],
    )
    resolved = tmp_path / "out" / "params.resolved.yaml"
    save_resolved(params, resolved)
    assert load_params(resolved) == params
    assert [p.name for p in resolved.parent.iterdir()] == ["params.resolved.yaml"]  # no temp left
    # Every key is written out, so the file documents the run on its own.
    assert "max_rows_per_shard: 400000" in resolved.read_text()


def test_params_dict_is_plain_and_json_able() -> None:
    data = params_dict(Params())
    assert list(data) == [
        "seed",
        "env",
        "collect",
        "vae",
        "lstm",
        "agent",
        "experiment",
        "eval",
        "baselines",
        "report",
    ]
    assert data["env"]["human_policy"] == "mixed"
    assert json.loads(json.dumps(data)) == data


def test_flatten_uses_dotted_keys() -> None:
    flat = flatten(params_dict(Params()))
    assert flat["vae.kl_weight"] == 1.0
    assert flat["env.num_humans"] == 3
    assert flat["seed"] == 0
    assert flatten({"a": {"b": {"c": 1}, "d": {}}}) == {"a.b.c": 1, "a.d": {}}


# --- the agent section (pipeline/agents/params.py) ----------------------------------------------


def test_agent_section_shares_the_library_dataclass(tmp_path: Path) -> None:
    from pipeline.agents.params import AgentParams

    params = load_params(
        write(tmp_path, "agent:\n  gamma: 0.95\n  trunk_sizes: [128, 128]\n"),
        ["agent.preset=paper", "agent.learning_rate=1e-3"],
    )
    assert isinstance(params.agent, AgentParams)
    assert params.agent == AgentParams(
        gamma=0.95, trunk_sizes=(128, 128), preset="paper", learning_rate=1e-3
    )
    assert load_params(write(tmp_path, "")).agent == AgentParams()
    resolved = tmp_path / "resolved.yaml"
    save_resolved(params, resolved)
    assert load_params(resolved) == params


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("agent:\n  gamma: 1.5\n", "agent.gamma: must be in [0, 1], got 1.5"),
        ("agent:\n  episodes: 1.5\n", "agent.episodes: expected an integer, got 1.5"),
        ("agent:\n  huber: 1\n", "agent.huber: expected true or false, got 1"),
        ("agent:\n  preset: fast\n", "agent.preset: must be one of shared, paper, got 'fast'"),
        ("agent:\n  trunk_sizes: 5\n", "agent.trunk_sizes: expected a list, got 5"),
        ("agent:\n  gama: 0.9\n", "unknown key 'agent.gama' (did you mean 'agent.gamma'?)"),
    ],
)
def test_agent_section_errors(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    assert error_of(path) == f"{path}: {expected}"
