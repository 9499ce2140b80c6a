"""Every option is checked when its config is built, and the CLI checks the whole config first.

A bad value in a pipeline TOML (``[split] method = "lscm"``) used to be a ``ValueError``
traceback after three stages had run. Now every field of every stage config is checked for its
type (an int where a float is asked is fine; a bool, which Python counts as an int, never is),
its range and its choices, as a :class:`ConfigError` naming the ``[table]`` and the key; the
solver's own options raise :class:`ConfigError` too (still a ``ValueError``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from meshes import tri_grid

import segparam.artifacts
import segparam.batch
import segparam.clean
import segparam.io
import segparam.pipeline
import segparam.remesh
import segparam.segment
import segparam.split
from segparam.cli import main
from segparam.errors import ConfigError, SegparamError
from segparam.pack import PackConfig
from segparam.parameterize import HessianSolver, parameterize_chart, solve_charts, tangent_frames
from segparam.pipeline import PipelineConfig, config_from_dict, load_config
from segparam.remesh import RemeshConfig
from segparam.segment import MAX_CHARTS, SegmentConfig
from segparam.split import SplitConfig

SECTIONS = {
    "remesh": RemeshConfig,
    "segment": SegmentConfig,
    "split": SplitConfig,
    "pack": PackConfig,
}

# (table, key): (values of a wrong type, values of the right type but out of range or unknown)
BAD = {
    ("remesh", "mode"): ([1, True], ["sometimes", "ON"]),
    ("remesh", "target_edge"): (["1.0", True], [0, -1.0, math.inf, math.nan]),
    ("remesh", "feature_angle"): (["30", True], [-1, 180.5, math.nan]),
    ("remesh", "iterations"): ([2.5, 10.0, True, "10"], [0, 1001]),
    ("segment", "n_charts"): (["12", 2.0, True], [0, -3, MAX_CHARTS + 1]),
    ("segment", "curvature_per_chart"): (["6.28", True], [0, -1, math.inf, math.nan]),
    ("segment", "max_charts"): ([1.5, True], [0, MAX_CHARTS + 1]),
    ("segment", "max_chart_faces"): (["20000", 2e4, True], [0, -1]),
    ("segment", "concave_weight"): (["1", False], [0, -0.5, math.nan]),
    ("segment", "convex_weight"): ([[0.2], True], [0, -0.2, math.inf]),
    ("segment", "proxy_faces"): ([2e4, True], [0]),
    ("segment", "smoothing"): ([1.5, True], [-1]),
    ("segment", "feature_angle"): (["60", True], [0, -10, 181]),
    ("segment", "rounding"): (["128", True], [-1, math.inf, math.nan]),
    ("split", "method"): ([1, True], ["lscm", "Hessian"]),
    ("split", "tangent"): ([0, True], ["normal", "svd"]),
    ("split", "max_depth"): ([6.0, True, "6"], [-1]),
    ("split", "max_distortion"): (["3", True], [0.5, 0, math.inf, math.nan]),
    ("split", "max_stretch"): (["1.01", True], [0.5, 0, math.inf, math.nan]),
    ("split", "min_split_gain"): (["7e-4", True], [-1e-3, math.inf, math.nan]),
    ("split", "min_faces"): ([8.5, True], [0, -1]),
    ("split", "n_jobs"): ([True, "2", 1.0], [-1]),
    ("split", "refine"): ([1, True], ["SLIM", "lbfgs"]),
    ("split", "angle_weight"): (["16", True], [-1, math.inf, math.nan]),
    ("split", "slit_above"): (["1.06", True], [0.5, 0, math.inf, math.nan]),
    ("pack", "resolution"): ([1024.0, True, "1024"], [0, -1, 16385]),
    ("pack", "padding"): ([2.0, True, "2"], [-1]),
    ("pack", "method"): ([1, True], ["skyline", "Raster"]),
    ("pack", "rotate"): ([1, 0, "yes", 1.0], ["true", "false"]),
    ("pack", "trim"): ([1, 0, "no", 1.0], ["true", "false"]),
    ("pack", "angle_steps"): ([6.0, True], [0, -6]),
    ("pack", "texels_per_unit"): (["64", True], [-1, math.inf, math.nan]),
    ("pack", "max_chart_size"): ([1.5, True, "8"], [-1]),
}

CASES = [
    pytest.param(table, key, value, id=f"{table}.{key}={value!r}:{kind}")
    for (table, key), (wrong_types, bad_values) in BAD.items()
    for kind, values in (("type", wrong_types), ("range", bad_values))
    for value in values
]


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return repr(value)


def assert_names(exc: pytest.ExceptionInfo, table: str, key: str) -> None:
    text = str(exc.value)
    assert "\n" not in text
    assert re.search(rf"\[{table}\] {key}\b", text), text


def test_every_key_of_every_config_has_bad_values():
    keys = {(t, f.name) for t, cls in SECTIONS.items() for f in dataclasses.fields(cls)}
    assert set(BAD) == keys


@pytest.mark.parametrize("table, key, value", CASES)
def test_a_bad_value_is_a_config_error_naming_the_table_and_key(table, key, value):
    with pytest.raises(ConfigError) as exc:
        config_from_dict({table: {key: value}})
    assert_names(exc, table, key)
    with pytest.raises(ConfigError) as exc:  # the same through PipelineConfig.replace
        PipelineConfig().replace(**{table: {key: value}})
    assert_names(exc, table, key)


@pytest.mark.parametrize("table, key, value", CASES)
def test_a_bad_value_in_a_toml_file_names_the_file_table_and_key(table, key, value, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(f"[{table}]\n{key} = {toml_value(value)}\n", encoding="utf-8")
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    assert str(exc.value).startswith(f"{path}: [{table}] ")
    assert_names(exc, table, key)


@pytest.mark.parametrize("table, key, value", CASES)
def test_the_stage_configs_check_every_field_themselves(table, key, value):
    """Built directly (the Python API), each stage config refuses the value, naming the key."""
    with pytest.raises(ConfigError, match=rf"^{key} is "):
        SECTIONS[table](**{key: value})


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"rotate": 1}, "rotate"),
        ({"rotate": "yes"}, "rotate"),
        ({"rotate": None}, "rotate"),
        ({"padding": True}, "padding"),
        ({"angle_steps": True}, "angle_steps"),
        ({"resolution": True, "padding": 0}, "resolution"),
    ],
)
def test_pack_config_refuses_bools_for_integers_and_a_rotate_that_is_not_a_bool(kwargs, key):
    # True is an int in Python; PackConfig, like every stage config, refuses it for an integer
    with pytest.raises(ConfigError, match=rf"^{key} is "):
        PackConfig(**kwargs)


def test_sections_of_the_wrong_type_are_config_errors():
    with pytest.raises(ConfigError, match=r"\[pack\] must be a PackConfig"):
        PipelineConfig(pack={"resolution": 512})
    with pytest.raises(ConfigError, match=r"\[split\] must be a table"):
        PipelineConfig().replace(split=5)
    with pytest.raises(ConfigError, match=r"\[remesh\] must be a table"):
        config_from_dict({"remesh": "off"})


def test_good_values_of_every_kind_are_accepted_and_stored_as_plain_python():
    cfg = config_from_dict(
        {
            "remesh": {"mode": "on", "target_edge": 1, "feature_angle": np.float32(45)},
            "segment": {
                "n_charts": np.int64(12),
                "curvature_per_chart": 3,
                "max_charts": MAX_CHARTS,
                "feature_angle": 180,
                "rounding": 0,
                "smoothing": 0,
            },
            "split": {"max_distortion": 1, "max_depth": 0, "n_jobs": np.int32(1)},
            "pack": {"resolution": 16384, "padding": 0, "rotate": False},
        }
    )
    assert cfg.remesh.target_edge == 1.0 and type(cfg.remesh.target_edge) is float
    assert type(cfg.remesh.feature_angle) is float
    assert cfg.segment.n_charts == 12 and type(cfg.segment.n_charts) is int
    assert type(cfg.segment.curvature_per_chart) is float
    assert type(cfg.split.max_distortion) is float and type(cfg.split.n_jobs) is int
    json.dumps(cfg.as_dict())  # the report's settings: JSON as they are
    assert SplitConfig(max_distortion=None).max_distortion is None
    assert RemeshConfig(target_edge=None).target_edge is None
    assert SegmentConfig(n_charts=None).n_charts is None


def test_the_bundled_pipelines_still_load():
    root = Path(__file__).resolve().parents[1] / "pipelines"
    for path in sorted(root.glob("*.toml")):
        load_config(path)
    assert load_config(root / "default.toml") == PipelineConfig()


def test_the_cli_max_charts_limit_is_the_librarys():
    from segparam import cli

    assert cli.MAX_CHARTS(str(MAX_CHARTS)) == MAX_CHARTS
    SegmentConfig(max_charts=MAX_CHARTS)


# ---------------------------------------------------------------------------------------------
# The solver's own options
# ---------------------------------------------------------------------------------------------


def disk():
    return tri_grid(6, 6)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"method": "lscm"}, "method"),
        ({"method": None}, "method"),
        ({"tangent": "normal"}, "tangent"),
        ({"min_points": 5}, "min_points"),
        ({"min_points": 6.0}, "min_points"),
        ({"min_points": True}, "min_points"),
        ({"n_neighbors": 3}, "n_neighbors"),
        ({"n_neighbors": "12"}, "n_neighbors"),
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"refine": "yes"}, "refine"),
        ({"refine": False}, "refine"),
    ],
)
def test_solver_options_are_config_errors(kwargs, key):
    with pytest.raises(ConfigError, match=rf"^{key} is ") as exc:
        parameterize_chart(*disk(), **kwargs)
    assert isinstance(exc.value, ValueError) and isinstance(exc.value, SegparamError)


def test_solver_options_are_checked_before_the_mesh():
    # Options first: not even the (missing) mesh is looked at.
    with pytest.raises(ConfigError, match="^method is 'lscm'"):
        HessianSolver(None, None, method="lscm")


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"seed": -1}, "seed"),
        ({"refine": "arap!"}, "refine"),
        ({"refine_iterations": -1}, "refine_iterations"),
        ({"refine_iterations": 2.0}, "refine_iterations"),
    ],
)
def test_solve_options_are_config_errors(kwargs, key):
    solver = HessianSolver(*disk())
    with pytest.raises(ConfigError, match=rf"^{key} is "):
        solver.solve(**kwargs)


def test_batched_solver_and_tangent_frames_options_are_config_errors():
    V, F = disk()
    vert_chart = np.zeros(len(V), dtype=np.int64)
    with pytest.raises(ConfigError, match="^tangent is"):
        solve_charts(V, F, vert_chart, tangent="normal")
    with pytest.raises(ConfigError, match="^refine is"):
        solve_charts(V, F, vert_chart, refine="none!")
    with pytest.raises(ConfigError, match="^tangent is"):
        tangent_frames(V, F, np.zeros(1, dtype=np.int64), np.zeros(0), tangent="svd")


def test_an_existing_value_error_caller_still_catches_them():
    with pytest.raises(ValueError, match="method"):
        parameterize_chart(*disk(), method="lscm")
    with pytest.raises(ValueError, match="method"):
        SplitConfig(method="lscm")


# ---------------------------------------------------------------------------------------------
# The command line: the whole config first, one line, exit code 2, no stage
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def no_stage(monkeypatch):
    """Every stage (and the mesh reader, Dask) fails the test if it runs."""

    def work(*args, **kwargs):
        raise AssertionError("a stage ran although the config is bad")

    for module, name in [
        (segparam.io, "load_mesh"),
        (segparam.pipeline, "build_atlas"),
        (segparam.pipeline, "pack_atlas"),
        (segparam.pipeline, "clean"),
        (segparam.pipeline, "remesh"),
        (segparam.pipeline, "segment"),
        (segparam.pipeline, "parameterize_charts"),
        (segparam.clean, "clean"),
        (segparam.remesh, "remesh"),
        (segparam.segment, "segment"),
        (segparam.split, "parameterize_charts"),
        (segparam.artifacts, "load_stage"),
        (segparam.batch, "require_dask"),
        (segparam.batch, "run_batch"),
    ]:
        monkeypatch.setattr(module, name, work)


def bad_toml(tmp_path: Path, text: str = '[split]\nmethod = "lscm"\n') -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_the_issue_command_is_one_line_exit_2_and_no_stage_ran(tmp_path, capsys, no_stage):
    bad = bad_toml(tmp_path)
    out = tmp_path / "badout"
    code = main(["atlas", "--config", str(bad), "-o", str(out), "--no-remesh"])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    assert captured.err.splitlines() == [
        f"segparam: error: {bad}: [split] method is 'lscm'; it must be one of 'hessian', "
        "'classic-hlle'"
    ]
    assert not out.exists()


@pytest.mark.parametrize(
    "command",
    [
        ["atlas", "mesh.obj", "-o", "out"],
        ["atlas", "mesh.obj", "-o", "out", "--resolution", "256", "--no-remesh"],
        ["remesh", "mesh.obj", "-o", "r.npz"],
        ["segment", "r.npz", "-o", "s.npz"],
        ["parameterize", "s.npz", "-o", "p.npz"],
        ["pack", "p.npz", "-o", "atlas"],
        ["batch", "mesh.obj", "-o", "many"],
    ],
    ids=lambda argv: " ".join(argv[:1] + argv[4:]),
)
@pytest.mark.parametrize(
    "text, words",
    [
        ('[split]\nmethod = "lscm"\n', ["[split] method", "'lscm'"]),
        ("[segment]\nsmoothing = true\n", ["[segment] smoothing", "True"]),
        ("[remesh]\niterations = 2.5\n", ["[remesh] iterations", "2.5"]),
        ('[pack]\nrotate = "yes"\n', ["[pack] rotate", "'yes'"]),
        ("[pack]\nresolution = 16385\n", ["[pack] resolution", "limit"]),
    ],
)
def test_every_command_checks_the_config_before_any_work(
    command, text, words, tmp_path, capsys, monkeypatch, no_stage
):
    monkeypatch.chdir(tmp_path)
    bad = bad_toml(tmp_path, text)
    code = main([*command, "--config", str(bad), "--quiet"])
    lines = capsys.readouterr().err.splitlines()
    assert code == 2, lines
    assert len(lines) == 1 and lines[0].startswith(f"segparam: error: {bad}: "), lines
    for word in words:
        assert word in lines[0], (word, lines)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]  # nothing written


def test_the_issue_command_in_a_fresh_process_prints_no_traceback(tmp_path):
    import subprocess
    import sys

    bad = bad_toml(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "segparam.cli", "atlas", "--config", str(bad), "-o",
         str(tmp_path / "badout"), "--no-remesh"],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines() == [
        f"segparam: error: {bad}: [split] method is 'lscm'; it must be one of 'hessian', "
        "'classic-hlle'"
    ]
    assert not (tmp_path / "badout").exists()
