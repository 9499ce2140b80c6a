"""Repacking existing uv islands (segparam.repack): islands found, shapes kept up to a rotation
and one common scale, broken islands re-charted with the reason."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from meshes import rigid, tri_grid

from segparam.errors import InvalidMeshError
from segparam.pack import PackConfig
from segparam.quality import signed_areas
from segparam.raster import footprint_conflicts
from segparam.repack import (
    REASON_FLIP,
    REASON_OUTSIDE,
    REASON_OVERLAP,
    REASON_OVERLAP_OTHER,
    RepackConfig,
    repack,
    uv_islands,
)

PACK = PackConfig(resolution=256, padding=2)


def _islands(pieces):
    """One mesh from ``(V, F, uv)`` pieces, each its own uv island (uv rows not shared)."""
    V, F, uv, offset = [], [], [], 0
    for Vi, Fi, uvi in pieces:
        V.append(Vi)
        F.append(Fi + offset)
        uv.append(uvi)
        offset += len(Vi)
    return np.vstack(V), np.vstack(F), np.vstack(uv)


def _place(uv, angle, scale, shift, mirror=False):
    c, s = np.cos(angle), np.sin(angle)
    out = uv @ np.array([[c, s], [-s, c]]) * scale + shift
    return out * [-1, 1] if mirror else out


def _similarity(X, Y):
    """Best ``Y ~ a X + b`` with ``a`` a complex number (rotation times scale, no mirror):
    ``(a, relative residual)``."""
    x = X[:, 0] + 1j * X[:, 1]
    y = Y[:, 0] + 1j * Y[:, 1]
    x0, y0 = x - x.mean(), y - y.mean()
    a = np.vdot(x0, y0) / np.vdot(x0, x0)
    return a, float(np.linalg.norm(a * x0 - y0) / np.linalg.norm(y0))


def _known_layout():
    """Three planar patches placed anywhere in 3-D, whose uv is their own grid (an isometry),
    laid out turned, one of them mirrored, at one common scale 0.2 (uv per 3-D length)."""
    Vg, Fg = tri_grid(8, 6)
    Vu, Fu = tri_grid(10, 6, width=1.5, height=2.0)
    Vc, Fc = rigid(Vu, seed=3), Fu
    Vs, Fs = tri_grid(5, 5, width=0.6)
    return _islands(
        [
            (Vg + [0, 0, 1.0], Fg, _place(Vg[:, :2], 0.3, 0.2, [0.1, 0.1])),
            (Vc, Fc, _place(Vu[:, :2], 2.0, 0.2, [0.5, 0.3])),
            (Vs - [0, 0, 1.0], Fs, _place(Vs[:, :2], -0.7, 0.2, [-0.2, 0.8], mirror=True)),
        ]
    )


def test_uv_islands_index_and_corner_forms():
    # two triangles sharing one uv corner are one island; a third apart is another
    Fu = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7]])
    np.testing.assert_array_equal(uv_islands(Fu), [0, 0, 1])
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2, 1], [5, 5], [6, 5], [5, 6]], float)
    np.testing.assert_array_equal(uv_islands(uv[Fu]), [0, 0, 1])
    np.testing.assert_array_equal(uv_islands(Fu[::-1]), [0, 1, 1])  # numbered by first face
    with pytest.raises(InvalidMeshError, match="face uv must be"):
        uv_islands(np.zeros((3, 4), dtype=int))


def test_keep_preserves_island_shapes_up_to_rotation_and_one_scale():
    V, F, uv = _known_layout()
    islands = uv_islands(F)
    r = repack(V, F, uv, config=RepackConfig(pack=PACK))
    assert r.kept.all() and r.recharted is None
    assert all(reasons == () for reasons in r.reasons)
    np.testing.assert_array_equal(r.uv_vertex[r.uv_F], F)
    assert r.uv.min() >= 0 and r.uv.max() <= 1
    scales = []
    texels = r.uv * np.array(r.packing.size, dtype=float)  # similar in texels
    for i in range(3):
        faces = np.flatnonzero(islands == i)
        a, residual = _similarity(uv[F[faces]].reshape(-1, 2), texels[r.uv_F[faces]].reshape(-1, 2))
        assert residual < 1e-9
        scales.append(abs(a))
        # no mirror added: every face keeps its winding (the mirrored island stays mirrored)
        before = np.sign(signed_areas(uv, F[faces]))
        assert np.array_equal(np.sign(signed_areas(r.uv, r.uv_F[faces])), before)
    np.testing.assert_allclose(scales, scales[0], rtol=1e-9)
    faces = [r.uv_F[r.chart_of_face == c] for c in range(3)]
    assert footprint_conflicts([r.uv] * 3, faces, resolution=r.packing.size, padding=2) == 0


def test_keep_from_a_trimesh_with_uv():
    V, F, uv = _known_layout()
    mesh = trimesh.Trimesh(V, F, visual=trimesh.visual.TextureVisuals(uv=uv), process=False)
    a = repack(mesh, config=RepackConfig(pack=PACK))
    b = repack(V, F, uv, F, config=RepackConfig(pack=PACK))
    np.testing.assert_allclose(a.uv, b.uv)
    with pytest.raises(InvalidMeshError, match="no uv"):
        repack(trimesh.Trimesh(V, F, process=False))
    # uv per face corner (equal corners welded) gives the same layout
    c = repack(V, F, None, uv[F], config=RepackConfig(pack=PACK))
    np.testing.assert_allclose(c.uv[c.uv_F], b.uv[b.uv_F], atol=1e-12)


def _broken_layout():
    """Six islands: 0 valid; 1 and 2 overlap each other; 3 has a flipped face; 4 leaves the
    square; 5 winds round past a full turn (overlaps itself, no flip)."""
    Vg, Fg = tri_grid(6, 5)
    g = Vg[:, :2] * 0.15
    flipped = g + [0.6, 0.05]
    inner = np.flatnonzero((Vg[:, 0] > 0.1) & (Vg[:, 0] < 0.9) & (Vg[:, 1] > 0.1))[0]
    flipped[inner] += [0.0, 0.2]  # pulled over its neighbours: faces turn over
    Vs, Fs = tri_grid(40, 3, width=4.0, height=0.2)
    turn = 2.6 * np.pi * Vs[:, 0] / 4.0
    radius = 0.12 + Vs[:, 1]
    spiral = np.c_[radius * np.cos(turn), radius * np.sin(turn)] * 0.5 + [0.75, 0.75]
    pieces = [
        (Vg, Fg, g + [0.05, 0.05]),
        (Vg + [2, 0, 0], Fg, g + [0.3, 0.05]),
        (Vg + [4, 0, 0], Fg, g + [0.35, 0.1]),
        (Vg + [6, 0, 0], Fg, flipped),
        (Vg + [8, 0, 0], Fg, g + [0.9, 0.4]),
        (Vs + [0, 3, 0], Fs, spiral),
    ]
    return _islands(pieces)


def test_repair_recharts_only_the_broken_islands_and_says_why():
    V, F, uv = _broken_layout()
    islands = uv_islands(F)
    r = repack(V, F, uv, config=RepackConfig(mode="repair", pack=PACK))
    assert r.kept.tolist() == [True, False, False, False, False, False]
    assert r.reasons[0] == ()
    assert REASON_OVERLAP_OTHER in r.reasons[1] and REASON_OVERLAP_OTHER in r.reasons[2]
    assert REASON_FLIP in r.reasons[3]
    assert r.reasons[4] == (REASON_OUTSIDE,)
    assert r.reasons[5] == (REASON_OVERLAP,)
    report = r.report()
    assert report["kept_islands"] == 1 and report["recharted_islands"] == 5
    assert report["islands"][4]["reasons"] == [REASON_OUTSIDE]
    # the kept island keeps its shape; the re-charted ones are bijective charts
    faces = np.flatnonzero(islands == 0)
    texels = r.uv * np.array(r.packing.size, dtype=float)  # similar in texels
    _, residual = _similarity(uv[F[faces]].reshape(-1, 2), texels[r.uv_F[faces]].reshape(-1, 2))
    assert residual < 1e-9
    assert all(c.quality.bijective for c in r.recharted.charts)
    np.testing.assert_array_equal(r.uv_vertex[r.uv_F], F)
    n = int(r.chart_of_face.max()) + 1
    faces = [r.uv_F[r.chart_of_face == c] for c in range(n)]
    assert footprint_conflicts([r.uv] * n, faces, resolution=r.packing.size, padding=2) == 0
    assert (signed_areas(r.uv, r.uv_F[r.chart_of_face > 0]) > 0).all()


def test_keep_refuses_what_it_cannot_pack():
    V, F, uv = _known_layout()
    flat = uv.copy()
    flat[F[uv_islands(F) == 1].ravel()] = [0.5, 0.5]  # island 1 collapsed to a point
    with pytest.raises(InvalidMeshError, match="island 1 has no uv area.*repair"):
        repack(V, F, flat)
    r = repack(V, F, flat, config=RepackConfig(mode="repair", pack=PACK))
    assert r.kept.tolist() == [True, False, True] and REASON_FLIP in r.reasons[1]
    with pytest.raises(InvalidMeshError, match="uv must have shape"):
        repack(V, F, uv[:, :1])
    with pytest.raises(InvalidMeshError, match="indices span"):
        repack(V, F, uv[:10])
    with pytest.raises(InvalidMeshError, match="NaN"):
        repack(V, F, uv * np.nan)
