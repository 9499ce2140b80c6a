"""Tests of the synthetic cortex-like meshes (segparam.synthetic)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from segparam import mesh, synthetic
from segparam.errors import InvalidMeshError
from segparam.synthetic import brain_like_parcels, brain_like_surface


def _angles(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m, 3) corner angles in degrees."""
    P = V[F]
    out = np.empty(F.shape)
    for k in range(3):
        a = P[:, (k + 1) % 3] - P[:, k]
        b = P[:, (k + 2) % 3] - P[:, k]
        cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        out[:, k] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def _signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    return float(np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6.0)


def _total_abs_curvature(V: np.ndarray, F: np.ndarray) -> float:
    """Sum over vertices of |angle defect| (discrete total absolute Gaussian curvature)."""
    defect = 2.0 * np.pi - np.bincount(F.ravel(), np.radians(_angles(V, F)).ravel(), len(V))
    return float(np.abs(defect).sum())


@pytest.fixture(scope="module")
def surface() -> tuple[np.ndarray, np.ndarray]:
    return brain_like_surface(20000, seed=3)


@pytest.fixture(scope="module")
def shared_surface():
    """``brain_like_surface(n_faces, **options)``, built once per module for each distinct set of
    arguments (defaults filled in, so ``folding=1.0`` and the default are one surface): several
    tests read the same 20k and 80k hemispheres (0.3-2.5 s each). The arrays are read-only, so
    no test can change what another one reads."""
    signature = inspect.signature(brain_like_surface)
    built: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def get(n_faces: int, **options) -> tuple[np.ndarray, np.ndarray]:
        bound = signature.bind(n_faces, **options)
        bound.apply_defaults()
        key = tuple(bound.arguments.items())
        if key not in built:
            V, F = brain_like_surface(n_faces, **options)
            V.flags.writeable = False
            F.flags.writeable = False
            built[key] = V, F
        return built[key]

    return get


@pytest.fixture(scope="module")
def small_parcels() -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    return synthetic._brain_parcels(
        12, mean_faces=500, min_faces=150, max_faces=1500, seed=1, style="gentle"
    )


def test_surface_is_closed_oriented_genus0(surface):
    V, F = surface
    assert V.dtype == np.float64 and V.shape[1] == 3
    assert F.dtype == np.int64 and F.shape[1] == 3
    assert np.array_equal(np.unique(F), np.arange(len(V)))
    _, count = mesh.edge_face_counts(F)
    assert np.all(count == 2)
    assert mesh.is_edge_manifold(F)  # also: every edge traversed once each way
    assert mesh.is_vertex_manifold(F).all()
    assert mesh.euler_characteristic(F) == 2
    assert mesh.boundary_loops(F) == []
    assert _signed_volume(V, F) > 0.0


def test_surface_is_radial_graph_so_embedded(surface):
    # the directions of the vertices triangulate the sphere without flips: no self-intersection
    V, F = surface
    U = V / np.linalg.norm(V, axis=1, keepdims=True)
    n = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    assert np.all(np.einsum("ij,ij->i", n, U[F].sum(axis=1)) > 0.0)


@pytest.mark.parametrize("n_faces", [100, 1001, 5000, 33333, 90000])
def test_face_count_near_target(n_faces):
    V, F = brain_like_surface(n_faces)
    assert abs(len(F) - n_faces) <= max(2, 0.01 * n_faces)
    assert mesh.euler_characteristic(F) == 2


@pytest.mark.parametrize("n_faces", [1000, 8000, 40000])
def test_gentle_triangle_quality(n_faces):
    V, F = brain_like_surface(n_faces, style="gentle", seed=1)
    min_angle = _angles(V, F).min(axis=1)
    assert np.percentile(min_angle, 1) >= 20.0
    assert min_angle.min() >= 10.0
    valence = np.bincount(F.ravel())
    assert abs(valence.mean() - 6.0) < 0.05
    assert valence.min() >= 4 and valence.max() <= 8


def test_deterministic_and_seeded():
    V1, F1 = brain_like_surface(3000, seed=5)
    V2, F2 = brain_like_surface(3000, seed=5)
    V3, F3 = brain_like_surface(3000, seed=6)
    assert V1.tobytes() == V2.tobytes() and F1.tobytes() == F2.tobytes()
    assert np.array_equal(F1, F3)  # same sphere triangulation, different folds
    assert not np.allclose(V1, V3)


def test_no_folding_is_smooth_ellipsoid(shared_surface):
    V0, F0 = brain_like_surface(20000, folding=0.0)
    V1, F1 = shared_surface(20000, folding=1.0)
    k0 = _total_abs_curvature(V0, F0)
    k1 = _total_abs_curvature(V1, F1)
    assert k0 == pytest.approx(4.0 * np.pi, rel=0.02)  # convex: Gauss-Bonnet, no negative K
    assert k1 > 4.0 * k0
    r = np.linalg.norm(V0, axis=1)
    assert 27.0 < r.min() and r.max() < 71.0


def test_parameters_change_the_folds(shared_surface):
    V, _ = brain_like_surface(20000, folding=0.5)
    W, _ = shared_surface(20000, folding=1.0)
    depth_half = np.ptp(np.linalg.norm(V, axis=1))
    depth_full = np.ptp(np.linalg.norm(W, axis=1))
    assert depth_half < depth_full
    Vh, _ = brain_like_surface(20000, frequency=0.6)
    assert not np.allclose(Vh, W)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_faces": 99},
        {"n_faces": 1000, "folding": -1.0},
        {"n_faces": 1000, "frequency": 0.0},
        {"n_faces": 1000, "irregularity": 1.5},
        {"n_faces": 1000, "style": "wild"},
        {"n_faces": 1000, "connectivity": "hexagonal"},
        {"n_faces": 1000, "surface": "inflated"},
        {"n_faces": 1000, "style": "gentle", "surface": "white"},
    ],
)
def test_surface_rejects_bad_arguments(kwargs):
    with pytest.raises(InvalidMeshError):
        brain_like_surface(**kwargs)


def test_is_disk_on_small_meshes():
    fan = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    assert synthetic._is_disk(fan)
    bowtie = np.array([[0, 1, 2], [0, 3, 4]])  # two triangles sharing a vertex
    assert not synthetic._is_disk(bowtie)
    annulus = np.array([[0, 1, 4], [1, 5, 4], [1, 2, 5], [2, 6, 5], [2, 3, 6], [3, 7, 6]])
    annulus = np.vstack([annulus, [[3, 0, 7], [0, 4, 7]]])
    assert not synthetic._is_disk(annulus)


def test_face_neighbors_match_mesh_face_adjacency(surface):
    _, F = surface
    adj = mesh.face_neighbors(F)
    pairs = np.sort(np.column_stack([np.repeat(np.arange(len(F)), 3), adj.ravel()]), axis=1)
    expected, _ = mesh.face_adjacency(F)
    assert np.array_equal(np.unique(pairs, axis=0), np.unique(expected, axis=0))


@pytest.mark.slow
def test_folding_adds_area():
    # only on fine meshes: coarse ones lengthen the folds at fixed depth and gain no area
    V, F = brain_like_surface(100000, style="gentle", seed=3)
    V0, F0 = brain_like_surface(100000, style="gentle", folding=0.0, seed=3)
    ratio = mesh.face_areas(V, F).sum() / mesh.face_areas(V0, F0).sum()
    assert 1.15 < ratio < 1.6


def _check_parcel(V: np.ndarray, F: np.ndarray) -> None:
    assert V.dtype == np.float64 and F.dtype == np.int64
    assert np.array_equal(np.unique(F), np.arange(len(V)))
    assert mesh.is_edge_manifold(F)
    assert mesh.is_vertex_manifold(F).all()
    assert mesh.connected_components(F)[0] == 1
    assert mesh.euler_characteristic(F) == 1
    assert len(mesh.boundary_loops(F)) == 1


def test_small_parcels_are_disks(small_parcels):
    parcels, hot = small_parcels
    assert len(parcels) == 12
    sizes = np.array([len(F) for _, F in parcels])
    assert sizes.min() >= 150 and sizes.max() <= 1500
    assert 300 < sizes.mean() < 800
    for V, F in parcels:
        _check_parcel(V, F)
        # outward winding: normals point away from the hemisphere centre on average
        n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        assert np.einsum("ij,ij->", n, V[F].mean(axis=1)) > 0.0
    assert hot.sum() >= 1


def test_parcels_deterministic():
    a = brain_like_parcels(6, mean_faces=150, min_faces=50, max_faces=450, seed=4)
    b = brain_like_parcels(6, mean_faces=150, min_faces=50, max_faces=450, seed=4)
    c = brain_like_parcels(6, mean_faces=150, min_faces=50, max_faces=450, seed=5)
    assert all(
        x[0].tobytes() == y[0].tobytes() and x[1].tobytes() == y[1].tobytes()
        for x, y in zip(a, b, strict=True)
    )
    assert any(
        x[0].shape != y[0].shape or not np.allclose(x[0], y[0]) for x, y in zip(a, c, strict=True)
    )


def test_parcels_reject_bad_bounds():
    with pytest.raises(InvalidMeshError):
        brain_like_parcels(5, mean_faces=100, min_faces=300, max_faces=3000)
    with pytest.raises(InvalidMeshError):
        brain_like_parcels(0)


@pytest.mark.slow
def test_atlas_parcels():
    parcels, hot = synthetic._brain_parcels(
        89, mean_faces=1000, min_faces=300, max_faces=3000, seed=0, style="gentle"
    )
    assert len(parcels) == 89
    sizes = np.array([len(F) for _, F in parcels])
    assert sizes.min() >= 300 and sizes.max() <= 3000
    assert 800 < sizes.mean() < 1250
    assert 0.10 <= hot.mean() <= 0.20
    for V, F in parcels:
        _check_parcel(V, F)
        # compact: the boundary is not much longer than a disc's of the same area
        B = mesh.boundary_edges(F)
        perimeter = np.linalg.norm(V[B[:, 0]] - V[B[:, 1]], axis=1).sum()
        assert perimeter**2 / (4.0 * np.pi * mesh.face_areas(V, F).sum()) < 6.0


def test_surface_statistics_on_convex_and_folded():
    # a convex closed surface: area equals its hull's, |K| integrates to 4 pi (Gauss-Bonnet)
    V, F = brain_like_surface(5000, folding=0.0)
    s = synthetic.surface_statistics(V, F)
    assert s["faces"] == len(F) and s["vertices"] == len(V)
    assert s["area_over_hull"] == pytest.approx(1.0, abs=0.01)
    assert s["abs_curvature"] == pytest.approx(1.0, abs=0.02)
    assert 0.0 < s["min_angle_p1"] <= s["min_angle_p5"] <= 60.0
    valence = np.bincount(F.ravel())
    assert s["valence_std"] == pytest.approx(valence.std())
    # a saddle-rich fold: negative curvature counts with its absolute value
    W, G = brain_like_surface(5000, folding=3.0)
    t = synthetic.surface_statistics(W, G)
    assert t["abs_curvature"] > 3.0 and t["area_over_hull"] > s["area_over_hull"]


# --------------------------------------------------------------------------------------------------
# the cortex style: as folded as fsaverage5's pial surface (issue 16)

# fsaverage5 left pial surface (nilearn's bundled copy), benchmarks/bench_brains.py
PIAL_AREA_OVER_HULL = 1.65
PIAL_ABS_CURVATURE = 69.2


def _check_like_pial(V: np.ndarray, F: np.ndarray) -> dict:
    s = synthetic.surface_statistics(V, F)
    assert s["area_over_hull"] == pytest.approx(PIAL_AREA_OVER_HULL, rel=0.15)
    assert s["abs_curvature"] == pytest.approx(PIAL_ABS_CURVATURE, rel=0.15)
    return s


def _direction_flips(V: np.ndarray, F: np.ndarray) -> int:
    """Triangles whose vertex directions are flipped on the sphere (0: radial graph, embedded)."""
    U = V / np.linalg.norm(V, axis=1, keepdims=True)
    n = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
    return int(np.sum(np.einsum("ij,ij->i", n, U[F].sum(axis=1)) <= 0.0))


@pytest.mark.parametrize("connectivity", ["uniform", "icosahedral"])
@pytest.mark.parametrize("n_faces", [5000, 20000])
def test_cortex_is_as_folded_as_real_pial(n_faces, connectivity, shared_surface):
    V, F = shared_surface(n_faces, connectivity=connectivity)
    s = _check_like_pial(V, F)
    assert s["min_angle_p1"] > 10.0  # fsaverage5 pial: 13.5
    assert _direction_flips(V, F) == 0


@pytest.mark.slow
@pytest.mark.parametrize("n_faces", [80000, 320000, 1000000])
def test_cortex_is_as_folded_as_real_pial_large(n_faces, shared_surface):
    V, F = shared_surface(n_faces)
    _check_like_pial(V, F)
    assert _direction_flips(V, F) == 0


def test_cortex_default_is_far_more_folded_than_gentle(shared_surface):
    V, F = shared_surface(20000)
    G, H = brain_like_surface(20000, style="gentle")
    cortex = synthetic.surface_statistics(V, F)
    gentle = synthetic.surface_statistics(G, H)
    assert cortex["abs_curvature"] > 5.0 * gentle["abs_curvature"]
    assert cortex["area_over_hull"] > gentle["area_over_hull"] + 0.3


def test_cortex_has_no_self_intersections():
    # an independent check of the radial-graph argument: pymeshlab's triangle-triangle tests
    import pymeshlab

    for connectivity in ("uniform", "icosahedral"):
        for surface in ("pial", "white"):
            V, F = brain_like_surface(5000, connectivity=connectivity, surface=surface, seed=2)
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(V, F))
            ms.compute_selection_by_self_intersections_per_face()
            assert ms.current_mesh().selected_face_number() == 0, (connectivity, surface)
            assert _direction_flips(V, F) == 0


def test_cortex_sulci_are_deep_and_narrow(shared_surface):
    # the groove profile: depth below the smooth ellipsoid along each vertex's ray
    V, F = shared_surface(80000, folding=1.0, seed=0)
    E, _ = brain_like_surface(80000, folding=0.0, seed=0)
    U = V / np.linalg.norm(V, axis=1, keepdims=True)
    r = synthetic._ellipsoid(U)[0]
    depth = r - np.linalg.norm(V, axis=1)
    assert depth.max() > 15.0  # primary sulci 17.9 mm deep (plus secondary ones)
    # steep walls: a sizeable share of the area faces sideways (normal far from the ray)
    N = mesh.face_normals(V, F)
    ray = V[F].mean(axis=1)
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    steep = np.einsum("ij,ij->i", N, ray) < np.cos(np.radians(60.0))
    area = mesh.face_areas(V, F)
    assert area[steep].sum() / area.sum() > 0.15
    assert len(E) == len(V)


def test_icosahedral_connectivity_like_a_template(shared_surface):
    V, F = shared_surface(20000, connectivity="icosahedral")
    assert len(F) == 20480 and len(V) == 10242  # fsaverage5's sizes
    valence = np.bincount(F.ravel())
    assert np.sum(valence == 5) == 12 and np.all(valence[valence != 5] == 6)
    s = synthetic.surface_statistics(V, F)
    assert s["valence_std"] < 0.05
    assert 10.0 < s["min_angle_p1"] < 20.0 and 14.0 < s["min_angle_p5"] < 25.0


def test_white_pial_pair_share_connectivity():
    W, V, F = synthetic.brain_like_pair(5000, connectivity="icosahedral", seed=4)
    V2, F2 = brain_like_surface(5000, connectivity="icosahedral", seed=4)
    W2, F3 = brain_like_surface(5000, connectivity="icosahedral", surface="white", seed=4)
    assert V.tobytes() == V2.tobytes() and W.tobytes() == W2.tobytes()
    assert np.array_equal(F, F2) and np.array_equal(F, F3)
    # white lies under pial along every vertex ray, by at least the cortical thickness
    U = V / np.linalg.norm(V, axis=1, keepdims=True)
    assert np.allclose(W / np.linalg.norm(W, axis=1, keepdims=True), U)
    gap = np.linalg.norm(V, axis=1) - np.linalg.norm(W, axis=1)
    assert gap.min() >= synthetic._THICKNESS - 1e-9
    assert mesh.face_areas(W, F).sum() < mesh.face_areas(V, F).sum()
    with pytest.raises(InvalidMeshError):
        synthetic.brain_like_pair(5000, surface="white")


@pytest.mark.parametrize("name", ["lh.pial.gii", "lh.pial.surf.gii", "lh.white.gii.gz"])
def test_gifti_export_loads_back(tmp_path, name):
    import nibabel as nib

    from segparam.io import load_mesh

    W, V, F = synthetic.brain_like_pair(2000, seed=1)
    X = W if "white" in name else V
    path = synthetic.save_gifti(tmp_path / name, X, F)
    assert path == tmp_path / name and sorted(p.name for p in tmp_path.iterdir()) == [name]
    image = nib.load(path)
    intents = [nib.nifti1.intent_codes.label[d.intent] for d in image.darrays]
    assert intents == ["pointset", "triangle"]
    assert image.darrays[0].meta["AnatomicalStructurePrimary"] == "CortexLeft"
    assert image.darrays[0].data.dtype == np.float32 and image.darrays[1].data.dtype == np.int32
    V2, F2 = load_mesh(path)
    assert np.array_equal(F2, F)
    assert np.abs(V2 - X).max() < 1e-4  # float32


def test_gifti_export_rejects_bad_arrays(tmp_path):
    with pytest.raises(InvalidMeshError):
        synthetic.save_gifti(tmp_path / "x.gii", np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(InvalidMeshError):
        synthetic.save_gifti(tmp_path / "x.gii", np.zeros((3, 3)), np.array([[0, 1, 3]]))
    assert list(tmp_path.iterdir()) == []


def test_cortex_parcels_are_disks_cut_from_folds():
    parcels = brain_like_parcels(10, mean_faces=460, min_faces=380, max_faces=560, seed=2)
    assert len(parcels) == 10
    for V, F in parcels:
        _check_parcel(V, F)
        assert 380 <= len(F) <= 560
    # folded like the cortex: the parcels carry far more |K| than gentle ones of the same size
    gentle = brain_like_parcels(
        10, mean_faces=460, min_faces=300, max_faces=700, seed=2, style="gentle"
    )

    def interior_abs_curvature(V, F):
        defect = np.abs(mesh.angle_defect(V, F))
        defect[np.unique(mesh.boundary_edges(F))] = 0.0
        return defect.sum()

    k = [interior_abs_curvature(V, F) for V, F in parcels]
    g = [interior_abs_curvature(V, F) for V, F in gentle]
    assert np.median(k) > 3.0 * np.median(g)
