"""The root configuration: JSON round trip, --set, --config, and the CLI's defaults."""

import dataclasses
import json

import pytest

from reassemble import cli
from reassemble.config import Config, default, from_dict, read_config, to_dict, with_setting
from reassemble.errors import ReassembleError
from reassemble.synth import BreakParams

from .conftest import SMALL_COW, shared_run


def _parse(*argv):
    return cli.build_parser().parse_args([str(a) for a in argv])


def test_round_trip_through_json():
    config = Config()
    for setting in ("seed=7", "radii=0.01,0.03", "gap=0.02", "thin_walls=yes", "fill_holes=0.1",
                    "segment.crease_angle=25", "features.signature_radii=none", "describe.max_memory=1e8",
                    "registration.plane_consensus=false", "assembly.group_rounds=2"):
        config = with_setting(config, setting)
    back = from_dict(json.loads(json.dumps(to_dict(config))))
    assert back == config and back != Config()
    assert back.radii == (0.01, 0.03) and back.features.signature_radii is None and back.thin_walls is True
    assert from_dict({}) == Config()  # what a file leaves out keeps its default


def test_set_overrides_one_value_with_its_type():
    config = with_setting(Config(), "segment.crease_angle=25")
    assert config.segment.crease_angle == 25.0 and isinstance(config.segment.crease_angle, float)
    assert dataclasses.replace(config, segment=Config().segment) == Config()  # nothing else changed
    assert with_setting(Config(), "segment.samples=1000").segment.samples == 1000
    assert with_setting(Config(), "gap=auto").gap is None
    assert with_setting(Config(break_=BreakParams(pieces=3)), "break.hurst=0.5").break_ == BreakParams(pieces=3,
                                                                                                        hurst=0.5)


@pytest.mark.parametrize("setting, message", [
    ("segment.no_such_option=1", "unknown option 'no_such_option'"),
    ("nosection.crease_angle=1", "unknown section 'nosection'"),
    ("no_such_option=1", "unknown option 'no_such_option'"),
    ("segment.crease_angle=steep", "not a number: 'steep'"),
    ("segment.samples=2.5", "not a whole number"),
    ("registration.plane_consensus=maybe", "not true or false"),
    ("segment.crease_angle", "not NAME=VALUE"),
    ("segment=1", "unknown option 'segment'"),
    ("break.hurst=0.5", "not used by this command"),
    ("segment.method=none", "segment.method must be one of learned, mixture"),
    ("segment.fallback=roughness", "segment.fallback must be one of learned, mixture"),
])
def test_set_errors_are_one_line(setting, message):
    with pytest.raises(ReassembleError, match=message) as err:
        with_setting(Config(), setting)
    assert "\n" not in str(err.value)


def test_read_config_names_the_file_and_the_option(tmp_path):
    path = tmp_path / "config.json"
    path.write_text(json.dumps({"segment": {"crease_angel": 25}}))
    with pytest.raises(ReassembleError, match=r"config.json: unknown option 'segment.crease_angel'"):
        read_config(path)
    path.write_text(json.dumps({"registration": {"tolerance": "small"}}))
    with pytest.raises(ReassembleError, match=r"config.json: registration.tolerance: not a number"):
        read_config(path)
    path.write_text(json.dumps({"features": {"signature_radii": 9}}))
    with pytest.raises(ReassembleError, match="signature_radii must be 1 to 3"):
        read_config(path)


def test_cli_defaults_are_the_config_defaults(tmp_path):
    for command in ("run", "match"):
        args = _parse(command, tmp_path, "--out", tmp_path / "o")
        assert cli._config(args) == Config()
        help_text = " ".join(cli.build_parser()._subparsers._group_actions[0].choices[command].format_help().split())
        assert f"(default {cli._size_text(default('describe.max_memory'))})" in help_text
        assert f"random seed (default {default('seed')})" in help_text
    args = _parse("break", "spot", "--pieces", 3, "--out", tmp_path / "p")
    assert cli._config(args, base=Config(break_=BreakParams(pieces=3))).break_ == BreakParams(pieces=3)
    help_text = " ".join(cli.build_parser()._subparsers._group_actions[0].choices["break"].format_help().split())
    assert f"(default {BreakParams(pieces=2).cut_edge:g})" in help_text


def test_cli_options_config_file_and_set_combine(tmp_path):
    path = tmp_path / "config.json"
    path.write_text(json.dumps({"seed": 3, "segment": {"crease_angle": 40.0}, "reference_size": 1.0}))
    args = _parse("run", tmp_path, "--out", tmp_path / "o", "--config", path, "--gap", "0.01",
                  "--max-memory", "2G", "--set", "segment.merge_angle=50", "--set", "seed=4")
    config = cli._config(args)
    assert (config.seed, config.gap, config.describe.max_memory) == (4, 0.01, 2e9)
    assert (config.segment.crease_angle, config.segment.merge_angle) == (40.0, 50.0)


def test_cli_unknown_setting_is_a_one_line_error(tmp_path, capsys):
    rc = cli.main(["run", str(tmp_path), "--out", str(tmp_path / "o"), "--set", "segment.crease=25"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("reassemble: error: --set segment.crease: unknown option 'crease'")
    assert err.count("\n") == 1 and not (tmp_path / "o").exists()


@pytest.mark.slow
@shared_run(SMALL_COW)
def test_config_json_reproduces_the_run(puzzles, tmp_path, capsys):
    puzzle_dir, run_dir = puzzles.puzzle(*SMALL_COW), puzzles.run(*SMALL_COW)  # a smoke-set case: shared
    written = json.loads((run_dir / "config.json").read_text())
    config = read_config(run_dir / "config.json")
    recorded = {k: v for k, v in written.items() if k not in ("format", "reference_size", "vertex_noise", "note")}
    assert to_dict(config) == recorded
    assert config.thin_walls is False and config.gap is not None  # decided from the data, recorded resolved
    rc = cli.main(["run", str(puzzle_dir / "fragments"), "--out", str(tmp_path / "again"), "--config",
                   str(run_dir / "config.json"), "--jobs", "1", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "again" / "transforms.json").read_bytes() == (run_dir / "transforms.json").read_bytes()
    assert (tmp_path / "again" / "config.json").read_bytes() == (run_dir / "config.json").read_bytes()
