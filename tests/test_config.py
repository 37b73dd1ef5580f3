"""One typed configuration: TOML round trip, partial files over the defaults, clear errors; the
method registry that the CLI and the docs read."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from ipr_shapes.cli import EXIT_INPUT_ERROR, build_parser, main
from ipr_shapes.config import Config, config_digest, config_to_toml, read_config
from ipr_shapes.errors import IprError
from ipr_shapes.inference import InferenceConfig
from ipr_shapes.likelihood import LikelihoodConfig
from ipr_shapes.methods import DEFAULT_METHOD, METHODS, get_method

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_whole_configuration_survives_a_round_trip_through_toml(tmp_path: Path):
    changed = dataclasses.replace(
        Config(),
        inference=InferenceConfig(
            max_samples=7, weighting="object", likelihood=LikelihoodConfig(alpha_per_m=8.0)
        ),
    )
    path = tmp_path / "run.toml"
    path.write_text(config_to_toml(changed))
    assert read_config(path) == changed
    assert read_config(path) != Config()
    assert config_digest(read_config(path)) == config_digest(changed) != config_digest(Config())


def test_a_file_gives_only_what_it_changes(tmp_path: Path):
    path = tmp_path / "run.toml"
    path.write_text("[inference]\nmax_samples = 3\n[inference.likelihood]\nalpha_per_m = 8\n")
    config = read_config(path)
    assert config.inference.max_samples == 3
    assert config.inference.likelihood.alpha_per_m == 8.0
    assert isinstance(config.inference.likelihood.alpha_per_m, float)
    assert config.perception == Config().perception
    assert config.inference.weighting == Config().inference.weighting


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[inference]\nmax_sample = 3\n", "inference.max_sample: no such setting"),
        ("[inferenc]\nmax_samples = 3\n", "inferenc: no such setting"),
        ('[inference]\nmax_samples = "3"\n', "inference.max_samples: expected int"),
        ("[inference]\nmax_samples = true\n", "inference.max_samples: expected int"),
        ('[inference]\nweighting = "mean"\n', "inference.weighting: expected 'hypothesis'"),
        (
            "[inference]\nmax_samples = 0\n",
            "InferenceConfig.max_samples must be None or an integer in [1, inf)",
        ),
        ("inference = 3\n", "inference: expected a table"),
        ("[inference\n", "not valid TOML"),
    ],
)
def test_a_bad_file_names_the_file_and_the_setting(tmp_path: Path, text: str, message: str):
    path = tmp_path / "run.toml"
    path.write_text(text)
    with pytest.raises(IprError) as error:
        read_config(path)
    assert message in str(error.value) and str(path) in str(error.value)


def test_config_show_prints_toml_that_infer_reads_back(tmp_path: Path, capsys):
    assert main(["config", "show"]) == 0
    shown = capsys.readouterr().out
    path = tmp_path / "all.toml"
    path.write_text(shown)
    assert read_config(path) == Config()
    (tmp_path / "one.toml").write_text("[carving]\nenabled = false\n")
    assert main(["config", "show", "--config", str(tmp_path / "one.toml")]) == 0
    assert "enabled = false" in capsys.readouterr().out.split("[carving]")[1].split("[")[0]


def test_infer_refuses_a_bad_config_before_any_work(scene_dir: Path, tmp_path: Path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[hypotheses]\ncount = 0\n")
    out = tmp_path / "out"
    assert main(["infer", str(scene_dir), "-o", str(out), "--config", str(bad)]) == (
        EXIT_INPUT_ERROR
    )
    error = capsys.readouterr().err
    assert (
        "HypothesisConfig.count must be an integer in [1, inf), got 0" in error
        and str(bad) in error
    )
    assert not out.exists()


def test_the_registry_is_what_the_cli_offers_and_the_readme_lists():
    parser = build_parser()
    infer = parser._subparsers._group_actions[0].choices["infer"]  # noqa: SLF001
    method = next(a for a in infer._actions if a.dest == "method")  # noqa: SLF001
    assert list(method.choices) == list(METHODS)
    assert method.default == DEFAULT_METHOD
    readme = README.read_text()
    for name in METHODS:
        assert f"`{name}`" in readme, f"README does not list method {name}"
    assert get_method(DEFAULT_METHOD).physics and get_method(DEFAULT_METHOD).actions
    assert not get_method("collision-checker").physics
    with pytest.raises(IprError, match="available: collision-checker"):
        get_method("ipr+gravity")


def test_infer_help_describes_every_method():
    completed = subprocess.run(
        [sys.executable, "-m", "ipr_shapes", "infer", "--help"], capture_output=True, text=True
    )
    assert completed.returncode == 0
    text = " ".join(completed.stdout.split())
    for method in METHODS.values():
        assert " ".join(method.description.split()) in text


def test_the_shipped_bin_picking_config_turns_the_colour_seams_on():
    """configs/bins.toml is what the README tells bin-picking users to pass: it must load and
    differ from the defaults exactly by the seams."""
    path = Path(__file__).resolve().parents[1] / "configs" / "bins.toml"
    config = read_config(path)
    assert config.perception.seams.enabled
    assert not Config().perception.seams.enabled
    seams_off = dataclasses.replace(
        config.perception, seams=dataclasses.replace(config.perception.seams, enabled=False)
    )
    assert dataclasses.replace(config, perception=seams_off) == Config()
