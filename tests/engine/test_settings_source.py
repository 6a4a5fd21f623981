"""One source of truth for settings: the CLI flags come from ReconstructSettings' fields, so a
new field is a new flag with no other edit; constants are defined once; settings import no
algorithm module."""

import argparse
import ast
import struct
import subprocess
import sys
from dataclasses import dataclass, fields
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import engine.reconstruct
import engine.reconstruct_to_file
from engine.__main__ import main
from engine.commands import reconstruct as reconstruct_command
from engine.commands.settings_args import add_settings_arguments
from engine.errors import Cancelled, InputError
from engine.settings import Choice, ReconstructSettings, setting

ROOT = Path(__file__).resolve().parents[2]


@dataclass
class WithNewSettings(ReconstructSettings):
    """ReconstructSettings as they would be after someone adds three fields."""

    smoothing: float = setting(0.5, "Smoothing", "How much the mesh is smoothed",
                               help="smoothing weight", low=0.0, high=1.0)
    keep_colours: bool = setting(True, "Keep Colours", "Carry the point colours to the mesh")
    fill: str = setting("holes", "Fill", "What to fill",
                        choices=(Choice("holes", "Holes", "Small holes"),
                                 Choice("nothing", "Nothing", "Leave every hole open")))
    passes: int = 4  # declared without setting(): still a flag, named after the field


def parser_for(settings_type):
    parser = argparse.ArgumentParser(prog="test")
    add_settings_arguments(parser, settings_type)
    return parser


def test_a_new_setting_becomes_a_flag_that_parses_into_the_settings():
    args = parser_for(WithNewSettings).parse_args(
        ["--smoothing", "0.25", "--no-keep-colours", "--fill", "nothing", "--passes", "7",
         "--resolution", "64"])
    assert WithNewSettings.from_attributes(args) == WithNewSettings(
        smoothing=0.25, keep_colours=False, fill="nothing", passes=7, resolution=64)
    assert WithNewSettings.from_attributes(parser_for(WithNewSettings).parse_args([])) == \
        WithNewSettings(), "no flags: the dataclass defaults"


def test_a_new_settings_range_and_choices_are_checked(capsys):
    args = parser_for(WithNewSettings).parse_args(["--smoothing", "1.5"])
    with pytest.raises(InputError, match=r"smoothing 1.5 is outside \[0.0, 1.0\]"):
        WithNewSettings.from_attributes(args)
    with pytest.raises(SystemExit):
        parser_for(WithNewSettings).parse_args(["--fill", "everything"])
    assert "invalid choice: 'everything'" in capsys.readouterr().err


def test_a_new_settings_help_has_its_text_and_default():
    text = " ".join(parser_for(WithNewSettings).format_help().split())
    assert "--smoothing SMOOTHING smoothing weight (default 0.5)" in text
    assert "--fill {holes,nothing} What to fill (default holes)" in text
    assert "--keep-colours, --no-keep-colours" in text


def test_the_reconstruct_command_keeps_every_flag_and_default():
    parser = argparse.ArgumentParser()
    reconstruct_command.add_arguments(parser)
    flags = {option for action in parser._actions for option in action.option_strings}
    assert flags >= {"--resolution", "--radius-mode", "--radius", "--parent-radius",
                     "--rho-min", "--rho-max", "--device", "--seed", "--min-component-faces",
                     "--outliers", "--outlier-ratio", "--udf-source", "--quiet"}
    args = parser.parse_args(["in.ply", "out.ply"])
    assert ReconstructSettings.from_attributes(args) == ReconstructSettings()
    assert {f.name: getattr(args, f.name) for f in fields(ReconstructSettings)} == \
        ReconstructSettings().to_dict()


def test_the_cli_hands_its_flags_to_reconstruct_as_settings(tmp_path, monkeypatch, capsys):
    cloud = tmp_path / "cloud.xyz"
    np.savetxt(cloud, np.random.default_rng(0).random((200, 3)))
    received = []

    def recording(points, path, settings, progress=None, cancel=None):
        received.append(settings)
        raise Cancelled()

    monkeypatch.setattr(engine.reconstruct_to_file, "reconstruct_to_file", recording)
    status = main(["reconstruct", str(cloud), str(tmp_path / "mesh.ply"), "--udf-source",
                   "nearest", "--resolution", "48", "--outlier-ratio", "3", "--quiet"])
    assert status == 130 and len(received) == 1
    assert received[0] == ReconstructSettings(udf_source="nearest", resolution=48,
                                              outlier_ratio=3.0)
    assert not (tmp_path / "mesh.ply").exists()


def test_udf_source_is_a_setting_that_reconstruct_follows():
    points = 0.5 * np.random.default_rng(1).normal(size=(3000, 3))
    points /= 2 * np.linalg.norm(points, axis=1, keepdims=True)
    settings = ReconstructSettings(resolution=32, device="cpu", udf_source="nearest")
    result = engine.reconstruct.reconstruct(points, settings)
    assert result.stats["udf_source"] == "nearest"
    assert len(result.mesh.faces) > 0
    with pytest.raises(InputError, match="udf source must be one of network, nearest"):
        ReconstructSettings(udf_source="exact").validate()


def test_settings_read_from_single_precision_values_are_the_decimals_typed():
    def single(value):
        return struct.unpack("<f", struct.pack("<f", value))[0]

    stored = SimpleNamespace(**ReconstructSettings(radius=0.018, rho_min=0.55,
                                                   outlier_ratio=3.3).to_dict())
    stored.radius, stored.rho_min, stored.outlier_ratio = (single(0.018), single(0.55),
                                                           single(3.3))
    assert stored.radius != 0.018
    read = ReconstructSettings.from_attributes(stored, single_precision=True)
    assert (read.radius, read.rho_min, read.outlier_ratio) == (0.018, 0.55, 3.3)
    assert ReconstructSettings.from_attributes(stored).radius == single(0.018), \
        "double-precision sources are read as they are"


def test_settings_import_no_algorithm_module():
    code = ("import sys, engine.settings; "
            "print(sorted(m for m in sys.modules if m.startswith('engine')))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, check=True)
    assert done.stdout.strip() == "['engine', 'engine.errors', 'engine.settings']"


def _assigned_names(path: Path) -> set:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {target.id for node in tree.body if isinstance(node, ast.Assign)
            for target in node.targets if isinstance(target, ast.Name)}


@pytest.mark.parametrize("name", ["DEVICES", "RADIUS_MODES", "UDF_SOURCES", "MAX_SEED",
                                  "DEFAULT_OUTLIER_RATIO"])
def test_each_shared_constant_is_defined_in_one_module(name):
    defined = [str(path.relative_to(ROOT)) for path in sorted((ROOT / "engine").rglob("*.py"))
               if name in _assigned_names(path)]
    assert len(defined) == 1, f"{name} is defined in {defined}"


def test_operators_do_not_import_the_ui():
    for path in sorted((ROOT / "operators").glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level >= 2:
                assert not (node.module or "").startswith("ui"), f"{path.name} imports ui"
