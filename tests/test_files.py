"""Files in and out: GIfTI surfaces, atomic writes and the stage artifacts."""

import gzip
import json
import os

import nibabel as nib
import numpy as np
import pytest
from meshes import tri_grid

from segparam.artifacts import load_stage, save_stage, stage_paths
from segparam.errors import MeshFileError
from segparam.io import atomic_path, load_mesh


def gifti_bytes(V: np.ndarray, F: np.ndarray | None) -> bytes:
    arrays = [nib.gifti.GiftiDataArray(V.astype(np.float32), intent="NIFTI_INTENT_POINTSET")]
    if F is not None:
        arrays.append(nib.gifti.GiftiDataArray(F.astype(np.int32), intent="NIFTI_INTENT_TRIANGLE"))
    return nib.gifti.GiftiImage(darrays=arrays).to_bytes()


@pytest.mark.parametrize("name", ["lh.pial.gii", "lh.pial.gii.gz", "LH.PIAL.GII.GZ"])
def test_a_gifti_surface_loads(name, tmp_path):
    V, F = tri_grid(5, 4)
    V[:, 2] = 0.25 * V[:, 0] * V[:, 1]
    V = V.astype(np.float32).astype(np.float64)  # GIfTI surfaces hold float32 positions
    data = gifti_bytes(V, F)
    (tmp_path / name).write_bytes(gzip.compress(data) if name.lower().endswith("gz") else data)
    V2, F2 = load_mesh(tmp_path / name)
    assert V2.dtype == np.float64 and F2.dtype == np.int64
    np.testing.assert_array_equal(V2, V)
    np.testing.assert_array_equal(F2, F)


def test_a_gifti_without_triangles_is_not_a_surface(tmp_path):
    V, _ = tri_grid(3, 3)
    (tmp_path / "points.gii").write_bytes(gifti_bytes(V, None))
    with pytest.raises(MeshFileError, match="points.gii: GIfTI file has no POINTSET and TRIANGLE"):
        load_mesh(tmp_path / "points.gii")
    (tmp_path / "plain.gii.gz").write_bytes(gifti_bytes(V, None))  # .gz that is not gzip
    with pytest.raises(MeshFileError, match="plain.gii.gz: not a readable"):
        load_mesh(tmp_path / "plain.gii.gz")


def test_atomic_path_replaces_the_file_only_when_the_block_succeeds(tmp_path):
    target = tmp_path / "out" / "a.txt"
    with atomic_path(target) as tmp:  # the folder is created
        assert tmp.parent == target.parent and tmp != target
        tmp.write_text("first")
        assert not target.exists()  # nothing at the final name until the block is over
    assert target.read_text() == "first"
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("failed while writing")
    assert target.read_text() == "first"  # the old file, whole
    assert sorted(p.name for p in target.parent.iterdir()) == ["a.txt"]  # no temporary left


def test_atomic_path_with_a_name_at_the_length_limit(tmp_path):
    target = tmp_path / ("n" * 250 + ".txt")
    with atomic_path(target) as tmp:
        tmp.write_text("x")
    assert target.read_text() == "x"


def test_save_stage_round_trip_and_same_bytes(tmp_path):
    V, F = tri_grid(4, 3)
    arrays = {"V": V, "F": F, "labels": np.arange(len(F)) % 2}
    info = {"stage": "segment", "charts": 2}
    out = save_stage(tmp_path / "s", arrays, info)  # the suffix is added
    assert out == tmp_path / "s.npz" and stage_paths(out) == (out, tmp_path / "s.json")
    back = load_stage(out, needs=("V", "F", "labels"))
    for key, value in arrays.items():
        np.testing.assert_array_equal(back[key], value)
        assert back[key].dtype == value.dtype
    assert json.loads((tmp_path / "s.json").read_text()) == info
    again = save_stage(tmp_path / "t.npz", arrays, info)
    assert again.read_bytes() == out.read_bytes()
    with pytest.raises(MeshFileError, match="lacks chart_uv"):
        load_stage(out, needs=("V", "chart_uv"))


def test_save_stage_failing_keeps_the_previous_artifact(tmp_path, monkeypatch):
    V, F = tri_grid(3, 3)
    out = save_stage(tmp_path / "r.npz", {"V": V, "F": F}, {"stage": "remesh"})
    before = out.read_bytes()

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full)
    with pytest.raises(MeshFileError, match="r.npz: cannot write the stage artifact: No space"):
        save_stage(out, {"V": V + 1, "F": F}, {"stage": "remesh"})
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r.npz"]


def test_a_chart_set_keeps_its_untried_charts_through_a_stage_file(tmp_path):
    # The split stage's record of the charts it cut before any solve goes into the stage file
    # and back; a file written before it was recorded reads as None (not recorded), not as 0.
    import trimesh

    from segparam.artifacts import charts_from_arrays, charts_to_arrays
    from segparam.split import parameterize_charts

    m = trimesh.creation.icosphere(2)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    labels = (V[F].mean(axis=1)[:, 2] > 0).astype(np.int64)  # two hemispheres: caps, cut at once
    cs = parameterize_charts(V, F, labels)
    assert cs.cut_untried.tolist() == [True, True]
    out = save_stage(tmp_path / "p", {"V": V, "F": F, **charts_to_arrays(cs)}, {"stage": "x"})
    back = charts_from_arrays(V, load_stage(out, needs=("V", "F")))
    assert back.cut_untried.tolist() == [True, True]
    old = {k: v for k, v in charts_to_arrays(cs).items() if k != "cut_untried"}
    assert charts_from_arrays(V, old).cut_untried is None
