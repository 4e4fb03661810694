"""The one parameter declaration: validation, dataclass fields, YAML and help all come from ParamSpec."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from face_reid_camera.common.param_table import (
    ParamError,
    ParamSpec,
    ParamTable,
    config_from_values,
    config_specs,
    param,
    validate_fields,
)


@dataclasses.dataclass(frozen=True)
class _Config:
    rate_hz: float = param(5.0, "Ticks per second (Hz).", low=0.0, high=100.0, low_open=True)
    count: int = param(3, "How many (count).", low=1, high=10)
    mode: str = param("a", "Which mode.", choices=("a", "b"))
    xyz_m: list[float] = param([0.0, 0.0, 1.0], "A position (m).", low=-5.0, high=5.0)
    not_a_param: int = 7

    def __post_init__(self) -> None:
        validate_fields(self)


def test_spec_checks_type_range_choices_and_length() -> None:
    spec = ParamSpec("gate", 0.5, "A probability (0..1).", low=0.0, high=1.0, high_open=True)
    assert spec.check(0) == 0.0 and isinstance(spec.check(0), float)  # an int is a fine float
    for bad, why in ((1.0, r"must be in \[0, 1\), got 1.0"), (math.nan, "must be in"), (True, "must be a float"),
                     ("x", "must be a float")):
        with pytest.raises(ParamError, match=why):
            spec.check(bad)
    xyz = ParamSpec("xyz", [0.0, 0.0, 2.5], "Position (m).", low=-10, high=10)
    assert xyz.length == 3 and xyz.check([1, 2, 3]) == [1.0, 2.0, 3.0]
    with pytest.raises(ParamError, match="list of 3 floats"):
        xyz.check([1.0, 2.0])
    with pytest.raises(ParamError, match="got 11"):
        xyz.check([1.0, 2.0, 11])
    with pytest.raises(ParamError, match="one of a, b"):
        ParamSpec("m", "a", "Mode of it.", choices=("a", "b")).check("c")
    with pytest.raises(ValueError, match="must be in"):
        ParamSpec("bad_default", 5, "Out of its own range.", low=0, high=1)


def test_dataclass_fields_are_the_declaration() -> None:
    specs = config_specs(_Config, "x.")
    assert [s.name for s in specs] == ["x.rate_hz", "x.count", "x.mode", "x.xyz_m"]
    assert specs[0].range_text() == "(0, 100]" and specs[2].choices == ("a", "b")
    assert _Config(count=4).count == 4
    with pytest.raises(ParamError, match=r"'rate_hz' must be in \(0, 100\], got 0.0"):
        _Config(rate_hz=0.0)
    with pytest.raises(ParamError, match="'mode' must be one of"):
        _Config(mode="z")
    built = config_from_values(_Config, {"x.rate_hz": 2, "x.count": 9, "x.mode": "b", "x.xyz_m": [1, 1, 1]}, "x.")
    assert built == _Config(2.0, 9, "b", [1.0, 1.0, 1.0]) and isinstance(built.rate_hz, float)


def test_table_yaml_round_trip_help_and_suggestions(tmp_path: Path) -> None:
    table = ParamTable("demo_node", config_specs(_Config), "a demo node", "demo --ros-args --params-file F")
    path = tmp_path / "demo.yaml"
    table.write_yaml(path)
    text = path.read_text()
    assert "/**:\n  ros__parameters:\n" in text and "# Ticks per second (Hz). (range (0, 100])" in text
    assert table.load_yaml(path) == table.defaults()
    assert "count (default 3; range [1, 10]): How many (count)." in table.help_text()
    with pytest.raises(ParamError, match="did you mean 'rate_hz'"):
        table.check_value("rate_hzz", 1.0)
    path.write_text("demo_node:\n  ros__parameters:\n    count: 11\n")
    with pytest.raises(ParamError, match=r"'count' must be in \[1, 10\], got 11"):
        table.load_yaml(path)


def test_a_tiered_table_shows_its_deployment_parameters_and_points_to_the_rest(tmp_path: Path) -> None:
    table = ParamTable("demo_node", config_specs(_Config, "x."), "a demo node", "demo",
                       deployment=["x.rate_hz"])
    assert table.tier("x.rate_hz") == "deployment" and table.tier("x.count") == "advanced"
    help_text, every = table.help_text(), table.help_text(advanced=True)
    assert "x.rate_hz" in help_text and "x.count" not in help_text
    assert "and 3 advanced parameters: --help-all" in help_text and "x.count" in every
    path = tmp_path / "demo.yaml"
    table.write_yaml(path)
    assert "rate_hz:" in path.read_text() and "count:" not in path.read_text()
    assert table.load_yaml(path) == table.defaults()  # the advanced ones at their defaults
    page = table.markdown()
    assert page.index("`x.rate_hz`") < page.index("`x.count`") and "| advanced |" in page
