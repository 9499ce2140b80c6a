"""Texel density (issue 17 part 6): ``texels_per_unit`` (the resolution follows, or is checked)
and ``max_chart_size`` (xatlas's maxChartSize: larger charts are scaled down), in PackConfig,
the TOML pipelines and the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from meshes import tri_grid

from segparam.cli import main
from segparam.errors import ConfigError, SolverError
from segparam.export import write_obj
from segparam.pack import PackConfig, min_area_rotation, pack_charts
from segparam.pipeline import config_from_dict
from segparam.quality import signed_areas
from segparam.raster import footprint_conflicts


def _charts():
    """Four flat charts of known 3-D area: a grid scaled 1, 2, 3 and 0.5 times (uv = 3-D)."""
    V, F = tri_grid(6, 6)
    scales = np.array([1.0, 2.0, 3.0, 0.5])
    uvs = [V[:, :2] * k for k in scales]
    areas = [float(np.abs(signed_areas(u, F)).sum()) for u in uvs]
    return uvs, [F] * 4, areas


def _texels(result):
    """Per chart, its packed uv in texels of the (possibly trimmed) texture."""
    return [u * np.array(result.size, dtype=float) for u in result.uvs]


def _density(result, faces, areas):
    """Per chart, texels per unit length: sqrt(area in texels / 3-D area)."""
    pairs = zip(_texels(result), faces, strict=True)
    texel_area = np.array([np.abs(signed_areas(u, f)).sum() for u, f in pairs])
    return np.sqrt(texel_area / np.asarray(areas))


def _longest_side(result):
    """Per chart, the longer side of its minimum-area box, in texels."""
    return np.array([np.ptp(min_area_rotation(u)[0], axis=0).max() for u in _texels(result)])


@pytest.mark.parametrize("resolution", [0, 512])
def test_texels_per_unit_is_honoured(resolution):
    uvs, faces, areas = _charts()
    r = pack_charts(uvs, faces, areas, config=PackConfig(resolution=resolution, texels_per_unit=40))
    np.testing.assert_allclose(_density(r, faces, areas), 40, rtol=1e-9)
    np.testing.assert_allclose(r.scale * r.width, 40, rtol=1e-12)
    if resolution:
        assert r.resolution == resolution
    else:  # it follows: at least the charts' area, and the charts fit
        assert np.sqrt(sum(areas)) * 40 < r.resolution <= 2 * np.sqrt(sum(areas)) * 40
    assert footprint_conflicts(r.uvs, faces, resolution=r.size, padding=2) == 0
    # twice the density: twice the texels a side
    r2 = pack_charts(uvs, faces, areas, config=PackConfig(resolution=0, texels_per_unit=80))
    np.testing.assert_allclose(_longest_side(r2), 2 * _longest_side(r), rtol=1e-9)


def test_texels_per_unit_that_cannot_fit_is_an_error():
    uvs, faces, areas = _charts()
    with pytest.raises(SolverError, match="do not fit a 128x128 texture .* at 40 texels"):
        pack_charts(uvs, faces, areas, config=PackConfig(resolution=128, texels_per_unit=40))


@pytest.mark.parametrize("texels_per_unit", [0.0, 40.0])
def test_max_chart_size_scales_the_larger_charts_down(texels_per_unit):
    uvs, faces, areas = _charts()
    free = pack_charts(
        uvs, faces, areas, config=PackConfig(resolution=256, texels_per_unit=texels_per_unit)
    )
    density = free.scale * free.width
    cfg = PackConfig(resolution=256, texels_per_unit=texels_per_unit, max_chart_size=60)
    r = pack_charts(uvs, faces, areas, config=cfg)
    sides, before = _longest_side(r), _longest_side(free)
    big = before > 60
    assert big.any() and (~big).any()
    np.testing.assert_allclose(sides[big], 60, rtol=1e-9)  # scaled down to the limit
    np.testing.assert_allclose(sides[~big], before[~big], rtol=1e-9)  # the others as they were
    np.testing.assert_allclose(_density(r, faces, areas)[~big], density, rtol=1e-9)
    assert footprint_conflicts(r.uvs, faces, resolution=r.size, padding=2) == 0


@pytest.mark.parametrize(
    ("pack", "message"),
    [
        ({"texels_per_unit": -1}, "texels_per_unit"),
        ({"texels_per_unit": "64"}, "texels_per_unit"),
        ({"texels_per_unit": float("inf")}, "texels_per_unit"),
        ({"max_chart_size": -1}, "max_chart_size"),
        ({"max_chart_size": 1.5}, "max_chart_size"),
        ({"resolution": 0}, "only with texels_per_unit above 0"),
        ({"resolution": -4, "texels_per_unit": 8}, "resolution"),
    ],
)
def test_density_options_are_validated(pack, message):
    with pytest.raises(ConfigError, match=message):
        PackConfig(**pack)
    with pytest.raises(ConfigError, match=r"pipe\.toml: \[pack\] .*" + message):
        config_from_dict({"pack": pack}, source="pipe.toml")


def test_density_options_from_a_toml_pipeline():
    cfg = config_from_dict({"pack": {"resolution": 0, "texels_per_unit": 12, "max_chart_size": 9}})
    assert (cfg.pack.resolution, cfg.pack.texels_per_unit, cfg.pack.max_chart_size) == (0, 12, 9)


@pytest.fixture
def plate(tmp_path):
    """A flat 2 x 1.5 plate (3 square units)."""
    V, F = tri_grid(12, 10, width=2.0, height=1.5)
    path = tmp_path / "plate.obj"
    write_obj(path, V, F)
    return path


def test_cli_texels_per_unit_sets_the_resolution(plate, tmp_path):
    out = tmp_path / "out"
    assert main(["atlas", str(plate), "-o", str(out), "--texels-per-unit", "50", "--quiet"]) == 0
    atlas = json.loads((out / "report.json").read_text())["atlas"]
    assert atlas["texels_per_unit"] == pytest.approx(50, rel=1e-9)
    assert np.sqrt(3.0) * 50 < atlas["resolution"] < 2 * np.sqrt(3.0) * 50


def test_cli_texels_per_unit_checked_against_the_resolution(plate, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["atlas", str(plate), "-o", str(out), "--texels-per-unit", "200", "--resolution", "256"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "at 200 texels per unit" in err and "256x256" in err
    assert not out.exists()
    args[-1] = "512"
    assert main([*args, "--quiet"]) == 0
    atlas = json.loads((out / "report.json").read_text())["atlas"]
    assert atlas["resolution"] == 512 and atlas["texels_per_unit"] == pytest.approx(200)


@pytest.mark.parametrize(
    "flag", [["--texels-per-unit", "0"], ["--texels-per-unit", "x"], ["--max-chart-size", "-2"]]
)
def test_cli_density_flags_are_checked(plate, tmp_path, capsys, flag):
    assert main(["atlas", str(plate), "-o", str(tmp_path / "out"), *flag]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_max_chart_size_above_every_chart_changes_nothing():
    uvs, faces, areas = _charts()
    plain = pack_charts(uvs, faces, areas, config=PackConfig(resolution=256))
    roomy = pack_charts(uvs, faces, areas, config=PackConfig(resolution=256, max_chart_size=250))
    for a, b in zip(plain.uvs, roomy.uvs, strict=True):
        np.testing.assert_array_equal(a, b)


def test_pack_stage_command_takes_the_density(plate, tmp_path):
    r, s, p = (str(tmp_path / f"{k}.npz") for k in "rsp")
    assert main(["remesh", str(plate), "-o", r, "--remesh", "off", "--quiet"]) == 0
    assert main(["segment", r, "-o", s, "--quiet"]) == 0
    assert main(["parameterize", s, "-o", p, "--quiet"]) == 0
    out = tmp_path / "out"
    assert main(["pack", p, "-o", str(out), "--texels-per-unit", "30", "--quiet"]) == 0
    atlas = json.loads((out / "report.json").read_text())["atlas"]
    assert atlas["texels_per_unit"] == pytest.approx(30)
    assert np.sqrt(3.0) * 30 < atlas["resolution"] < 2 * np.sqrt(3.0) * 30
