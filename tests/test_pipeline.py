import json

import numpy as np
import pytest
import trimesh
from meshes import plate_with_holes, spherical_cap, tri_grid

from segparam.errors import ConfigError, InvalidMeshError
from segparam.mesh import face_areas
from segparam.pack import footprint_conflicts
from segparam.pipeline import PipelineConfig, build_atlas, config_from_dict, load_config
from segparam.quality import chart_quality, distortion, signed_areas
from segparam.synthetic import brain_like_surface

FAST = PipelineConfig().replace(pack={"resolution": 512})


def icosphere():
    m = trimesh.creation.icosphere(3)
    return np.asarray(m.vertices), np.asarray(m.faces)


def scan_with_holes():
    """Two components: a wavy sheet with two holes punched in it, and a capped cylinder stub."""
    V, F = tri_grid(30, 30)
    V[:, 2] = 0.1 * np.sin(5 * V[:, 0]) * np.cos(4 * V[:, 1])
    c = V[F].mean(1)
    hole = (np.hypot(c[:, 0] - 0.3, c[:, 1] - 0.4) < 0.1) | (
        np.hypot(c[:, 0] - 0.7, c[:, 1] - 0.5) < 0.12
    )
    m = trimesh.creation.cylinder(radius=0.2, height=0.5, sections=24)
    m.apply_translation([2.0, 0, 0])
    W, G = np.asarray(m.vertices), np.asarray(m.faces)
    return np.vstack([V, W]), np.vstack([F[~hole], G + len(V)])


MESHES = {
    "sphere": icosphere,
    "genus2 plate": plate_with_holes,
    "scan with holes": scan_with_holes,
    "cap": spherical_cap,
}


def check_atlas(atlas):
    """The acceptance checks, recomputed independently of the pipeline's own figures."""
    V, F, uv, uvF = atlas.V, atlas.F, atlas.uv, atlas.uv_F
    assert np.array_equal(atlas.uv_vertex[uvF], F)  # every face has uvs, for its own vertices
    assert uv.min() >= 0 and uv.max() <= 1
    area = signed_areas(uv, uvF)
    assert (area > 0).all()  # no flipped triangle and no mirrored chart
    uvs = [uv[np.unique(uvF[atlas.chart_of_face == k])] for k in range(atlas.n_charts)]
    faces = []
    for k in range(atlas.n_charts):
        rows, local = np.unique(uvF[atlas.chart_of_face == k].ravel(), return_inverse=True)
        faces.append(local.reshape(-1, 3))
    # Charts never share a texel at the atlas resolution (a rasterized overlap test).
    assert footprint_conflicts(uvs, faces, resolution=atlas.packing.size, padding=0) == 0
    for k, c in enumerate(atlas.charts.charts):
        q = chart_quality(V[c.vertices], c.local_F, uvs[k])
        assert q.bijective
    report = json.loads(json.dumps(atlas.report()))
    a = report["atlas"]
    assert a["charts"] == atlas.n_charts and a["flipped_triangles"] == 0
    assert a["utilization"] == pytest.approx(area.sum(), rel=1e-9)
    d = distortion(V[atlas.uv_vertex], uvF, uv * np.array(atlas.packing.size))  # in texels
    assert a["angle_distortion"] == pytest.approx(d["angle_distortion"])
    assert a["l2_stretch"] == pytest.approx(d["l2_stretch"])
    per_chart_faces = sum(r["faces"] for r in report["charts"])
    assert per_chart_faces == len(F)
    for k, r in enumerate(report["charts"]):  # a cut's vertices: uv copies of one mesh vertex
        mine = atlas.chart_of_face == k
        assert r["cut_vertices"] == len(np.unique(uvF[mine])) - len(np.unique(F[mine]))
    assert a["charts_cut_open"] == sum(r["cut_vertices"] > 0 for r in report["charts"])
    seg = report["segmentation"]  # charts cut before a solve were not bijective on a first try
    assert seg["cut_untried"] == int(atlas.charts.cut_untried.sum())
    assert seg["first_pass_bijective"] + seg["cut_untried"] <= seg["charts"]
    assert sum(r["area"] for r in report["charts"]) == pytest.approx(face_areas(V, F).sum())
    return report


@pytest.mark.parametrize("name", list(MESHES))
@pytest.mark.parametrize("remesh", ["auto", "off"])
def test_atlas_acceptance(name, remesh):
    V, F = MESHES[name]()
    atlas = build_atlas(V, F, FAST.replace(remesh={"mode": remesh}), seed=0)
    report = check_atlas(atlas)
    if remesh == "off":
        # Positions and faces are exactly the (clean) input's: only uvs are added.
        assert np.array_equal(atlas.V, atlas.cleaning.V) and np.array_equal(
            atlas.F, atlas.cleaning.F
        )
    assert report["input"]["faces"] == len(F)


@pytest.mark.slow
@pytest.mark.parametrize("n_faces", [20_000, 60_000])
def test_brain_like_surfaces(n_faces):
    V, F = brain_like_surface(n_faces, seed=2)
    atlas = build_atlas(V, F, PipelineConfig(), seed=0)
    check_atlas(atlas)


def test_deterministic_for_a_seed():
    V, F = icosphere()
    a = build_atlas(V, F, FAST, seed=4)
    b = build_atlas(V, F, FAST, seed=4)
    assert np.array_equal(a.uv, b.uv) and np.array_equal(a.uv_F, b.uv_F)


def test_nothing_lost_accounting():
    V, F = tri_grid(12, 12)
    F = np.vstack([F, F[:5], [[0, 0, 1]], [[0, 1, 2]]])  # duplicates, a repeated index
    atlas = build_atlas(V, F, FAST.replace(remesh={"mode": "off"}))
    kept = atlas.cleaning.face_index
    removed = atlas.cleaning.removed_faces
    assert sorted(np.r_[kept, removed].tolist()) == list(range(len(F)))
    assert len(atlas.F) == len(kept)
    summary = atlas.report()["cleaning"]
    assert json.dumps(summary)  # JSON-ready, names the removed faces


@pytest.mark.slow
def test_split_workers_start_before_cleaning_and_are_the_ones_used(monkeypatch):
    import segparam.pipeline as pipeline
    import segparam.split as split

    monkeypatch.setattr(pipeline, "PARALLEL_MIN_FACES", 0)  # a small mesh takes the big path
    monkeypatch.setattr(split, "PARALLEL_MIN_FACES", 0)
    events, pools = [], []
    real_start, real_clean, real_new = split.start_workers, pipeline.clean, split._new_pool
    monkeypatch.setattr(
        pipeline, "start_workers", lambda c: events.append("start") or real_start(c)
    )
    monkeypatch.setattr(pipeline, "clean", lambda V, F: events.append("clean") or real_clean(V, F))
    monkeypatch.setattr(split, "_new_pool", lambda jobs: pools.append(jobs) or real_new(jobs))
    V, F = plate_with_holes()
    cfg = FAST.replace(remesh={"mode": "off"})
    parallel = build_atlas(V, F, cfg.replace(split={"n_jobs": 2}))
    assert events == ["start", "clean"] and pools == [2]  # one pool, started first
    serial = build_atlas(V, F, cfg.replace(split={"n_jobs": 1}))
    assert pools == [2]  # one job: no worker
    assert np.array_equal(parallel.uv, serial.uv) and np.array_equal(parallel.uv_F, serial.uv_F)


def test_too_large_mesh_is_refused_before_work(monkeypatch):
    import segparam.pipeline as pipeline

    monkeypatch.setattr(pipeline, "MAX_FACES", 10)
    V, F = tri_grid(5, 5)
    with pytest.raises(InvalidMeshError, match="limit is 10"):
        build_atlas(V, F)


def test_config_files_load_and_reject_unknown_keys(tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "pipelines"
    for path in sorted(root.glob("*.toml")):
        assert isinstance(load_config(path), PipelineConfig)
    bad = tmp_path / "bad.toml"
    bad.write_text("[pack]\nresolutoin = 10\n")
    with pytest.raises(ConfigError, match="unknown key 'resolutoin' in \\[pack\\]"):
        load_config(bad)
    with pytest.raises(ConfigError, match="unknown section"):
        config_from_dict({"packing": {}})
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "missing.toml")
    (tmp_path / "broken.toml").write_text("[pack\n")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(tmp_path / "broken.toml")


def test_default_toml_matches_the_dataclass_defaults():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "pipelines"
    assert load_config(root / "default.toml") == PipelineConfig()


def test_default_toml_lists_every_key():
    # As its header says: every key with its default, the ones without a value commented out.
    import dataclasses
    import re
    from pathlib import Path

    from segparam.pipeline import _SECTIONS, tomllib  # tomli on Python 3.10

    text = (Path(__file__).resolve().parents[1] / "pipelines" / "default.toml").read_text()
    tables = tomllib.loads(text)
    section = None
    commented = set()
    for line in text.splitlines():  # loop over the file's lines: the commented-out keys
        if m := re.match(r"\[(\w+)\]", line):
            section = m.group(1)
        elif m := re.match(r"# (\w+) = ", line):
            commented.add((section, m.group(1)))
    for name, cls in _SECTIONS.items():
        for f in dataclasses.fields(cls):
            if f.default is None:
                assert (name, f.name) in commented, (name, f.name)
            else:
                assert f.name in tables[name], (name, f.name)


def test_a_chart_slit_at_its_cone_is_one_chart_with_its_cut_in_the_report():
    # A flat grid with a cone one edge from its rim: one chart, cut along that edge (the cone
    # slit of the split stage); its uvs hold the rim vertex twice, and the report says so.
    V, F = tri_grid(6, 6)
    V = np.c_[V[:, :2], np.zeros(len(V))]
    V[int(np.argmin(((V[:, :2] - [0.5, 0.2]) ** 2).sum(axis=1))), 2] = 0.15
    atlas = build_atlas(V, F, PipelineConfig().replace(remesh={"mode": "off"}), seed=0)
    report = check_atlas(atlas)
    assert report["atlas"]["charts"] == 1 and report["atlas"]["charts_cut_open"] == 1
    assert report["charts"][0]["cut_vertices"] == 1
    plain = PipelineConfig().replace(remesh={"mode": "off"}, split={"slit_above": None})
    report = check_atlas(build_atlas(V, F, plain, seed=0))
    assert report["atlas"]["charts_cut_open"] == 0
