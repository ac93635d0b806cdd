"""params.yaml loading: defaults, overrides, one-line errors, round trip."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel

from socnav_wm.agents.baselines import OrcaBaselineParams, SfmBaselineParams, make_baseline
from socnav_wm.agents.params import VARIANT_NAMES, AgentParams
from socnav_wm.config import (
    STAGE_SECTIONS,
    ConfigError,
    Params,
    flatten,
    load_params,
    params_dict,
    save_resolved,
)
from socnav_wm.env.params import EnvParams

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "params.yaml"
PAPER = ROOT / "configs" / "paper.yaml"
TINY = ROOT / "tests" / "tiny.yaml"


def write(tmp_path: Path, text: str, name: str = "params.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def error_of(path: Path, overrides: tuple[str, ...] = (), overlays: tuple[Path, ...] = ()) -> str:
    with pytest.raises(ConfigError) as info:
        load_params(path, overrides, overlays)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- defaults and the shipped style ------------------------------------------------------------


def test_empty_file_gives_every_default(tmp_path: Path) -> None:
    params = load_params(write(tmp_path, ""))
    assert params == Params()
    assert params.seed == 0
    assert params.env == EnvParams()
    assert (params.collect.episodes, params.collect.num_envs) == (6000, 512)
    assert params.collect.max_rows_per_shard == 400_000
    assert (params.vae.latent_dim, params.vae.hidden_dim, params.vae.kl_weight) == (16, 256, 0.01)
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
    def check(model: type[BaseModel], prefix: str) -> None:
        for name, field in model.model_fields.items():
            assert field.description, f"{prefix}{name} has no docstring"
            if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
                check(field.annotation, f"{prefix}{name}.")

    check(Params, "")


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
            "env.humans_see_robot=true",
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
    assert params.env.humans_see_robot is True
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
    assert message == (f"{tmp_path / 'params.yaml'}: vae.batch_size: must be > 0, got -3")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("vae:\n  val_fraction: 0.8\n", "vae.val_fraction: must be <= 0.5, got 0.8"),
        ("vae:\n  kl_weight: -0.1\n", "vae.kl_weight: must be >= 0, got -0.1"),
        ("vae:\n  learning_rate: .inf\n", "vae.learning_rate: must be finite, got inf"),
        ("lstm:\n  seq_len: 1\n", "lstm.seq_len: must be >= 2, got 1"),
        ("collect:\n  episodes: 0\n", "collect.episodes: must be > 0, got 0"),
        ("seed: -1\n", "seed: must be >= 0, got -1"),
        ("seed: true\n", "seed: expected an integer, got True"),
        ("vae:\n  batch_size: 512.0\n", "vae.batch_size: expected an integer, got 512.0"),
        ("baselines:\n  orca:\n    time_horizon: 0\n", "baselines.orca.time_horizon: must be > 0"),
        (
            "baselines:\n  sfm:\n    anisotropy: 2.0\n",
            "baselines.sfm.anisotropy: must be in [0, 1]",
        ),
        ("baselines:\n  orca: 3\n", "baselines.orca: expected a mapping of keys, got 3"),
        ("vae:\n  device: tpu\n", "vae.device: must be one of auto, cpu, cuda, got 'tpu'"),
        ("env:\n  human_policy: bogus\n", "env.human_policy: must be one of mixed, sfm, orca"),
        ("env:\n  room_size: -1\n", "env.room_size: must be > 0"),
        ("env:\n  num_humans: true\n", "env.num_humans: expected an integer, got True"),
        ("env:\n  swept_collision: 'no'\n", "env.swept_collision: expected true or false"),
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
        ("vae.batch_size=-3", "--set vae.batch_size=-3: vae.batch_size: must be > 0, got -3"),
        ("env.room_size=-1", "--set env.room_size=-1: env.room_size: must be > 0"),
        ("env.human_policy=x", "--set env.human_policy=x: env.human_policy: must be one of"),
        ("vae.batch_size=[1", "--set vae.batch_size=[1: not valid YAML ("),
        (  # an error inside the value still names the --set that wrote the whole value
            "agent.trunk_sizes=[512,abc]",
            "--set agent.trunk_sizes=[512,abc]: agent.trunk_sizes.1: expected an integer, "
            "got 'abc'",
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
        "planning",
        "planning_model",
        "prediction",
        "report",
        "studies",
    ]
    assert data["env"]["human_policy"] == "mixed"
    assert json.loads(json.dumps(data)) == data


def test_flatten_uses_dotted_keys() -> None:
    flat = flatten(params_dict(Params()))
    assert flat["vae.kl_weight"] == 0.01
    assert flat["env.num_humans"] == 3
    assert flat["seed"] == 0
    assert flatten({"a": {"b": {"c": 1}, "d": {}}}) == {"a.b.c": 1, "a.d": {}}


# --- the agent section (socnav_wm/agents/params.py) ----------------------------------------------


def test_agent_section_shares_the_library_model(tmp_path: Path) -> None:
    params = load_params(
        write(tmp_path, "agent:\n  gamma: 0.95\n  trunk_sizes: [128, 128]\n"),
        ["agent.per_variant.maspm.gamma=0.9", "agent.learning_rate=1e-3"],
    )
    assert isinstance(params.agent, AgentParams)
    assert params.agent == AgentParams(
        gamma=0.95,
        trunk_sizes=(128, 128),
        per_variant={"maspm": {"gamma": 0.9}},
        learning_rate=1e-3,
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
        ("agent:\n  preset: paper\n", "unknown key 'agent.preset'"),
        ("agent:\n  backend: torch\n", "unknown key 'agent.backend'"),
        ("agent:\n  trunk_sizes: 5\n", "agent.trunk_sizes: expected a list, got 5"),
        ("agent:\n  gama: 0.9\n", "unknown key 'agent.gama' (did you mean 'agent.gamma'?)"),
        ("agent:\n  buffer_size: 10\n", "agent.buffer_size: must be >= batch_size (128), got 10"),
        (
            "agent:\n  per_variant:\n    fast: {gamma: 0.9}\n",
            "agent.per_variant: unknown variant 'fast'; expected some of dueling-dqn,",
        ),
        (
            "agent:\n  per_variant:\n    maspm: {gamma: 2.0}\n",
            "agent.per_variant.maspm.gamma: must be in [0, 1], got 2.0",
        ),
        (
            "agent:\n  per_variant:\n    maspm: {gama: 0.9}\n",
            "agent.per_variant.maspm.gama: unknown option",
        ),
        (  # the result must validate too: a cross-field check inside one variant
            "agent:\n  per_variant:\n    maspm: {buffer_size: 10}\n",
            "agent.per_variant.maspm.buffer_size: must be >= batch_size (128), got 10",
        ),
        ("agent:\n  per_variant: [1]\n", "agent.per_variant: expected a mapping of keys"),
    ],
)
def test_agent_section_errors(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    assert error_of(path).startswith(f"{path}: {expected}"), error_of(path)


def test_direct_construction_errors_are_one_line_and_named() -> None:
    for build, key in (
        (lambda: EnvParams(num_humans=-1), "env.num_humans: must be >= 0, got -1"),
        (lambda: EnvParams(room_size=1.0), "env.room_size: a 1.0 m room"),
        (lambda: AgentParams(batch_size=0), "agent.batch_size: must be > 0, got 0"),
        (lambda: AgentParams(gamma=True), "agent.gamma: expected a number, got True"),
        (lambda: OrcaBaselineParams(time_horizon=0), "baselines.orca.time_horizon: must be > 0"),
        (lambda: SfmBaselineParams(tau=1), "baselines.sfm.tau: unknown option"),
    ):
        with pytest.raises(ValueError) as info:
            build()
        message = str(info.value)
        assert "\n" not in message and message.startswith(key), message


def test_replace_validates_and_keeps_the_rest() -> None:
    env = EnvParams().replace(num_humans=5)
    assert env.num_humans == 5 and env.room_size == EnvParams().room_size
    agent = AgentParams().replace(trunk_sizes=[64], gamma=0.9)
    assert agent.trunk_sizes == (64,) and agent.gamma == 0.9
    with pytest.raises(ValueError, match=r"^agent\.buffer_size: must be >= batch_size"):
        AgentParams().replace(buffer_size=8)
    with pytest.raises(ValueError, match=r"^env\.colour: unknown option"):
        EnvParams().replace(colour="red")
    with pytest.raises(ValueError, match=r"^env: unknown option\(s\) colour"):
        EnvParams.from_dict({"colour": "red"})
    assert EnvParams.from_dict(EnvParams().to_dict()) == EnvParams()
    assert AgentParams.from_dict(AgentParams().to_dict()) == AgentParams()
    assert AgentParams().to_dict()["trunk_sizes"] == [512, 128]  # a plain list
    assert hash(AgentParams(per_variant={"maspm": {"gamma": 0.9}})) is not None


def test_resolved_applies_the_variants_overrides() -> None:
    shared = AgentParams()
    assert shared.resolved("maspm") is shared
    agent = AgentParams(per_variant={"maspm": {"gamma": 0.9, "trunk_sizes": [32, 32]}})
    maspm = agent.resolved("maspm")
    assert (maspm.gamma, maspm.trunk_sizes, maspm.per_variant) == (0.9, (32, 32), {})
    assert agent.resolved("dueling-dqn") == shared
    with pytest.raises(ValueError, match="variant: unknown 'nope'"):
        agent.resolved("nope")


# --- the defaults are params.yaml -----------------------------------------------------------------


def test_code_defaults_equal_the_shipped_params_yaml() -> None:
    assert params_dict(Params()) == params_dict(load_params(SHIPPED))
    assert Params() == load_params(SHIPPED)


def test_every_key_of_the_shipped_params_yaml_is_a_field() -> None:
    raw = yaml.safe_load(SHIPPED.read_text(encoding="utf-8"))

    def check(values: dict, model: type[BaseModel], prefix: str) -> None:
        for key, value in values.items():
            assert key in model.model_fields, f"{prefix}{key} is not a field"
            annotation = model.model_fields[key].annotation
            if isinstance(annotation, type) and issubclass(annotation, BaseModel):
                assert isinstance(value, dict), f"{prefix}{key}"
                check(value, annotation, f"{prefix}{key}.")

    check(raw, Params, "")


def test_baseline_defaults_are_the_controllers_defaults() -> None:
    params = load_params(SHIPPED)
    assert params.baselines.orca == OrcaBaselineParams()
    assert params.baselines.sfm == SfmBaselineParams()
    assert make_baseline("orca", **params.baselines.orca.to_dict()).config == OrcaBaselineParams()


# --- overlays ---------------------------------------------------------------------------------


def test_overlays_merge_mapping_by_mapping_in_order(tmp_path: Path) -> None:
    base = write(tmp_path, "seed: 1\nvae:\n  kl_weight: 0.5\n  batch_size: 64\nlstm:\n")
    first = write(
        tmp_path, "vae:\n  kl_weight: 0.25\nbaselines:\n  orca:\n    time_horizon: 3.0\n", "a.yaml"
    )
    second = write(tmp_path, "vae:\n  kl_weight: 0.125\nlstm:\n  hidden_dim: 8\n", "b.yaml")
    params = load_params(base, ["vae.kl_weight=0.0625"], [first, second])
    assert params.seed == 1
    assert params.vae.batch_size == 64  # kept: the overlays only touch kl_weight
    assert params.vae.kl_weight == 0.0625  # the --set comes last
    assert params.lstm.hidden_dim == 8
    assert params.baselines.orca.time_horizon == 3.0
    assert params.baselines.orca.safety_margin == OrcaBaselineParams().safety_margin
    assert load_params(base, (), [first, second]).vae.kl_weight == 0.125


def test_overlay_errors_name_the_overlay(tmp_path: Path) -> None:
    base = write(tmp_path, "vae:\n  batch_size: 64\n")
    bad = write(tmp_path, "vae:\n  kl_weight: -1.0\n", "bad.yaml")
    assert error_of(base, (), (bad,)) == f"{bad}: vae.kl_weight: must be >= 0, got -1.0"
    unknown = write(tmp_path, "vae:\n  kl_wieght: 1.0\n", "unknown.yaml")
    assert error_of(base, (), (unknown,)).startswith(f"{unknown}: unknown key 'vae.kl_wieght'")
    assert (
        error_of(base, (), (tmp_path / "none.yaml",)) == f"{tmp_path / 'none.yaml'}: file not found"
    )
    broken = write(tmp_path, "vae: [1\n", "broken.yaml")
    assert error_of(base, (), (broken,)).startswith(f"{broken}: not valid YAML (line ")
    listed = write(tmp_path, "- 1\n", "list.yaml")
    assert error_of(base, (), (listed,)) == f"{listed}: expected a mapping of sections, got list"
    # a bad value in the base file still names the base file
    base = write(tmp_path, "vae:\n  patience: 0\n")
    assert error_of(base, (), (TINY,)).startswith(f"{base}: vae.patience: must be > 0")


def test_paper_overlay_reproduces_the_per_variant_table() -> None:
    paper = load_params(SHIPPED, ["agent.episodes=10"], [PAPER]).agent
    assert set(paper.per_variant) == set(VARIANT_NAMES)
    vanilla = paper.resolved("dueling-dqn")
    assert (vanilla.gamma, vanilla.buffer_size, vanilla.polyak) == (0.99, 200_000, 0.995)
    assert (vanilla.optimizer, vanilla.learning_rate, vanilla.grad_clip) == ("adam", 1e-4, 0.5)
    assert (vanilla.epsilon_decay, vanilla.epsilon_min) == (0.995, 0.01)
    assert (vanilla.batch_size, vanilla.learning_starts, vanilla.trunk_sizes) == (
        64,
        64,
        (512, 128),
    )
    assert (vanilla.huber, vanilla.n_step, vanilla.decode_latents) == (False, 1, False)
    wm = paper.resolved("wm-dueling-dqn")
    assert (wm.optimizer, wm.amsgrad, wm.weight_decay) == ("adamw", True, 0.01)
    step = paper.resolved("2stepahead")
    assert (step.epsilon_decay, step.epsilon_min, step.optimizer) == (0.9995, 0.1, "adamw")
    for name in ("maspm", "2stepahead-maspm"):
        maspm = paper.resolved(name)
        assert (maspm.gamma, maspm.buffer_size, maspm.polyak) == (0.98, 1_000_000, 0.99)
        assert (maspm.epsilon_decay, maspm.epsilon_min, maspm.optimizer) == (0.998, 0.01, "adam")
    assert paper.resolved("maspm").learning_starts == 64
    assert paper.resolved("2stepahead-maspm").learning_starts == 128
    assert paper.resolved("maspm").episodes == 10  # run scale is not part of the table
    for name in VARIANT_NAMES:  # the paper's reward and observation order
        resolved = paper.resolved(name)
        assert (resolved.progress_reward, resolved.sort_humans) == (0, False)
        assert resolved.per_variant == {}


def test_tiny_overlay_loads() -> None:
    params = load_params(SHIPPED, (), [TINY])
    assert (params.seed, params.collect.episodes, params.agent.trunk_sizes) == (1, 40, (32,))
    assert params.experiment.variants == ["dueling-dqn", "2stepahead-maspm"]


# --- deep overrides -----------------------------------------------------------------------------


def test_overrides_at_any_depth(tmp_path: Path) -> None:
    params = load_params(
        write(tmp_path, "baselines:\n  orca:\n"),
        [
            "baselines.orca.time_horizon=3",
            "baselines.sfm.side_bias=0.25",
            "agent.per_variant.maspm.gamma=0.9",
            "agent.per_variant.maspm.trunk_sizes=[16]",
        ],
    )
    assert params.baselines.orca.time_horizon == 3.0
    assert params.baselines.sfm.side_bias == 0.25
    assert params.agent.per_variant == {"maspm": {"gamma": 0.9, "trunk_sizes": [16]}}
    assert params.agent.resolved("maspm").trunk_sizes == (16,)


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("baselines.orca.tau=1", "--set baselines.orca.tau=1: unknown key 'baselines.orca.tau'"),
        (
            "baselines.orca.time_horizn=1",
            "--set baselines.orca.time_horizn=1: unknown key 'baselines.orca.time_horizn' "
            "(did you mean 'baselines.orca.time_horizon'?)",
        ),
        ("baselines.orca=3", "--set baselines.orca=3: 'baselines.orca' is a section; use"),
        ("baselines.orca.time_horizon=0", "--set baselines.orca.time_horizon=0: baselines.orca."),
        (
            "agent.per_variant.maspm.gamma=2.0",
            "--set agent.per_variant.maspm.gamma=2.0: agent.per_variant.maspm.gamma: must be in",
        ),
        ("agent.gamma.x=1", "--set agent.gamma.x=1: unknown key 'agent.gamma.x'"),
    ],
)
def test_deep_override_errors(tmp_path: Path, override: str, expected: str) -> None:
    message = error_of(write(tmp_path, ""), (override,))
    assert message.startswith(expected), message


# --- what each stage writes ---------------------------------------------------------------------


def test_save_resolved_writes_only_the_given_sections(tmp_path: Path) -> None:
    params = load_params(SHIPPED, ["seed=4", "agent.gamma=0.9"])
    out = tmp_path / "params.yaml"
    save_resolved(params, out, STAGE_SECTIONS["collect"])
    written = yaml.safe_load(out.read_text())
    assert list(written) == ["seed", "env", "collect"]
    assert written["seed"] == 4
    back = load_params(out)
    assert (back.seed, back.env, back.collect) == (params.seed, params.env, params.collect)
    # a change in a section the stage does not read leaves the file unchanged
    before = out.read_bytes()
    save_resolved(
        load_params(SHIPPED, ["seed=4", "agent.gamma=0.5"]), out, ("seed", "env", "collect")
    )
    assert out.read_bytes() == before
    save_resolved(params, out, STAGE_SECTIONS["report"])
    written = yaml.safe_load(out.read_text())
    assert list(written) == ["env", "agent", "eval", "report"]
    assert written["agent"] == {"solved_window": 100, "solved_success_rate": 0.9}
    save_resolved(params, out, ("env", "baselines.orca"))
    assert yaml.safe_load(out.read_text())["baselines"] == {"orca": params.baselines.orca.to_dict()}
    with pytest.raises(ValueError, match="unknown section 'nope'"):
        save_resolved(params, out, ("nope",))


def test_stage_sections_follow_dvc_yaml() -> None:
    stages = {
        **yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"],
        **yaml.safe_load((ROOT / "studies" / "dvc.yaml").read_text())["stages"],
        **yaml.safe_load((ROOT / "scenarios" / "dvc.yaml").read_text())["stages"],
    }
    sections = STAGE_SECTIONS
    assert set(sections) <= set(stages)
    for name, stage in stages.items():
        listed = stage.get("do", stage).get("params", [])
        expected = tuple("baselines" if entry == "baselines.${item}" else entry for entry in listed)
        # A stage that reads no params (study_claims merges files) has no entry.
        assert sections.get(name, ()) == expected, name


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("planning_model: {seeds: [-1]}", "planning_model.seeds: must be non-negative"),
        ("planning_model: {seeds: [0, 0]}", "a seed is listed twice"),
        ("planning_model: {val_fraction: 1.0}", "planning_model.val_fraction"),
        ("planning_model: {horizn: 4}", "unknown key 'planning_model.horizn'"),
    ],
)
def test_planning_model_errors(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_text(text + "\n")
    with pytest.raises(ConfigError, match=re.escape(expected)):
        load_params(path)
