import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from meshes import spherical_cap, tri_grid

from segparam import mesh
from segparam.errors import InvalidMeshError


def tetrahedron():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return V, F


def torus(n=16, m=8, R=2.0, r=0.7):
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    u, v = 2 * np.pi * i / n, 2 * np.pi * j / m
    V = np.stack(
        [(R + r * np.cos(v)) * np.cos(u), (R + r * np.cos(v)) * np.sin(u), r * np.sin(v)], -1
    ).reshape(-1, 3)
    idx = np.arange(n * m).reshape(n, m)
    a, b = idx, np.roll(idx, -1, 0)
    c, d = np.roll(b, -1, 1), np.roll(idx, -1, 1)
    F = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return V, F


def annulus(n=24, rings=4):
    i, j = np.meshgrid(np.arange(n), np.arange(rings), indexing="ij")
    th, r = 2 * np.pi * i / n, 1 + j / (rings - 1)
    V = np.stack([r * np.cos(th), r * np.sin(th), 0 * r], -1).reshape(-1, 3)
    idx = np.arange(n * rings).reshape(n, rings)
    a, b = idx[:, :-1], np.roll(idx, -1, 0)[:, :-1]
    c, d = np.roll(idx, -1, 0)[:, 1:], idx[:, 1:]
    # (a, c, b) runs counter-clockwise seen from +z.
    F = np.concatenate(
        [np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    return V, F


@pytest.mark.parametrize(
    "V, F, message",
    [
        (np.zeros((4, 2)), [[0, 1, 2]], "shape"),
        (np.zeros((4, 3)), np.zeros((0, 3), int), "no faces"),
        ([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]], "NaN"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], r"span \[0, 3\]"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 1]], "repeat a vertex"),
        ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], "zero area"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2.5]], "integers"),
    ],
)
def test_check_mesh_rejects_bad_input(V, F, message):
    with pytest.raises(InvalidMeshError, match=message):
        mesh.check_mesh(V, F)


def test_check_mesh_returns_canonical_dtypes():
    V, F = mesh.check_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    assert V.dtype == np.float64 and F.dtype == np.int64


def test_grid_counts_and_topology():
    V, F = tri_grid(6, 5)
    E, _ = mesh.edges(F)
    loops = mesh.boundary_loops(F)
    assert len(loops) == 1 and len(loops[0]) == 2 * (6 + 5) - 4
    assert len(V) - len(E) + len(F) == mesh.euler_characteristic(F) == 1
    assert mesh.genus(F) == 0
    assert mesh.is_edge_manifold(F) and mesh.is_vertex_manifold(F).all()


def test_boundary_loops_are_ordered_and_follow_winding():
    V, F = annulus()
    loops = mesh.boundary_loops(F)
    assert len(loops) == 2 and mesh.genus(F) == 0
    E = {tuple(e) for e in mesh.boundary_edges(F)}
    for loop in loops:
        assert all((a, b) in E for a, b in zip(loop, np.roll(loop, -1), strict=True))
    # The outer loop of a counter-clockwise annulus runs counter-clockwise, the inner one clockwise.
    assert (np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])[:, 2] > 0).all()
    P = [(V[lp, :2], V[np.roll(lp, -1), :2]) for lp in loops]
    area = [(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]).sum() / 2 for p, q in P]
    radius = [np.linalg.norm(V[lp[0], :2]) for lp in loops]
    assert (
        np.sign(area[int(np.argmax(radius))]) == 1 and np.sign(area[int(np.argmin(radius))]) == -1
    )


def test_closed_surfaces_genus():
    assert mesh.genus(tetrahedron()[1]) == 0
    assert mesh.genus(torus()[1]) == 1
    assert mesh.boundary_loops(torus()[1]) == []


def test_components():
    V, F = tri_grid(4, 4)
    F2 = np.concatenate([F, F + len(V)])
    count, labels = mesh.connected_components(F2)
    assert count == 2 and (labels[: len(F)] == labels[0]).all() and labels[-1] != labels[0]


def test_bowtie_vertex_is_not_manifold():
    F = np.array([[0, 1, 2], [0, 3, 4]])
    manifold = mesh.is_vertex_manifold(F)
    assert not manifold[0] and manifold[1:].all()


def _fans_by_walk(F, v):
    """Reference: count the fans around v by a plain union-find over its corners' link edges."""
    parent = {}

    def find(x):
        while parent.setdefault(x, x) != x:
            x = parent[x]
        return x

    for f in F:
        if v in f:
            k = list(f).index(v)
            a, b = find(f[(k + 1) % 3]), find(f[(k + 2) % 3])
            parent[a] = b
    return len({find(x) for x in list(parent)})


@pytest.mark.parametrize("seed", range(5))
def test_vertex_manifold_matches_a_per_vertex_walk(seed):
    # Random soups with shared vertices: bowties, fans split in two, non-manifold edges.
    rng = np.random.default_rng(seed)
    F = rng.integers(0, 12, size=(25, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    manifold = mesh.is_vertex_manifold(F, 12)
    for v in range(12):
        assert manifold[v] == (_fans_by_walk(F, v) <= 1), v


def _is_disk_by_definition(F, holes):
    if not mesh.is_edge_manifold(F) or not mesh.is_vertex_manifold(F).all():
        return False
    if mesh.connected_components(F)[0] != 1:
        return False
    b = len(mesh.boundary_loops(F)) if len(mesh.boundary_edges(F)) else 0
    if b == 0 or (not holes and b != 1):
        return False
    return mesh.euler_characteristic(F) == 2 - b


@pytest.mark.parametrize("seed", range(8))
def test_is_disk_matches_its_definition(seed):
    # Random subsets of a grid: disks, disks with holes, several pieces, pinched vertices.
    rng = np.random.default_rng(seed)
    _, F = tri_grid(7, 7)
    for keep in (0.95, 0.8, 0.6):
        G = F[rng.random(len(F)) < keep]
        for holes in (True, False):
            try:
                expected = _is_disk_by_definition(G, holes)
            except InvalidMeshError:  # a pinched boundary has no loops to list
                expected = False
            assert mesh.is_disk(G, holes=holes) == expected


def test_non_manifold_edge():
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert not mesh.is_edge_manifold(F)


def test_gauss_bonnet_angle_defect():
    # Sum of angle defects (boundary turning angles included) is 2 pi chi.
    for V, F in [tetrahedron(), torus(), spherical_cap(), tri_grid(5, 5)]:
        total = mesh.angle_defect(V, F).sum()
        assert total == pytest.approx(2 * np.pi * mesh.euler_characteristic(F), abs=1e-9)


def test_normals_and_areas():
    V, F = tri_grid(5, 5)
    assert mesh.face_areas(np.eye(3), np.array([[0, 1, 2]]))[0] == pytest.approx(np.sqrt(3) / 2)
    assert np.allclose(mesh.face_normals(V, F), [0, 0, 1])
    assert np.allclose(mesh.vertex_normals(V, F), [0, 0, 1])
    Vt, Ft = tetrahedron()
    centroid_dir = Vt[Ft].mean(1) - Vt.mean(0)
    assert (np.einsum("ij,ij->i", mesh.face_normals(Vt, Ft), centroid_dir) > 0).all()
    # With the areas: the same bits as the two functions (a degenerate face included).
    rng = np.random.default_rng(0)
    for V, F in [(rng.normal(size=(50, 3)) * 1e3, rng.integers(0, 50, (200, 3))), torus()]:
        N, area = mesh.face_normals(V, F, return_areas=True)
        assert np.array_equal(N, mesh.face_normals(V, F))
        assert np.array_equal(area, mesh.face_areas(V, F))


def test_face_neighbors_and_is_disk():
    V, F = tri_grid(5, 4)
    N = mesh.face_neighbors(F)
    assert (N == -1).sum() == len(mesh.boundary_edges(F))
    f, k = np.nonzero(N >= 0)
    # The neighbour across edge (a, b) holds the same edge, reversed.
    a, b = F[f, k], F[f, (k + 1) % 3]
    G = F[N[f, k]]
    assert ((G == a[:, None]).any(1) & (G == b[:, None]).any(1)).all()
    assert mesh.is_disk(F) and mesh.is_disk(F, holes=False)
    Va, Fa = annulus()
    assert mesh.is_disk(Fa) and not mesh.is_disk(Fa, holes=False)
    assert not mesh.is_disk(tetrahedron()[1])  # closed
    assert not mesh.is_disk(torus()[1])
    assert not mesh.is_disk(np.array([[0, 1, 2], [0, 3, 4]]))  # bowtie


def test_plane_basis_is_orthonormal_right_handed_and_never_degenerate():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200, 3))
    n = np.vstack([n, np.eye(3), -np.eye(3)])  # the axes: x takes the y-axis helper
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    b1, b2 = mesh.plane_basis(n)
    for a, b in [(b1, b1), (b2, b2)]:
        np.testing.assert_allclose((a * b).sum(1), 1.0, atol=1e-14)
    for a, b in [(b1, b2), (b1, n), (b2, n)]:
        np.testing.assert_allclose((a * b).sum(1), 0.0, atol=1e-14)
    np.testing.assert_allclose(np.cross(b1, b2), n, atol=1e-14)  # (b1, b2, n) right-handed
    # the x axis itself: b1 = x cross y = z, b2 = x cross z = -y
    b1, b2 = mesh.plane_basis(np.array([[1.0, 0, 0]]))
    np.testing.assert_array_equal(b1, [[0, 0, 1.0]])
    np.testing.assert_array_equal(b2, [[0, -1.0, 0]])


def test_submesh_renumbers_the_faces_it_keeps():
    F = np.array([[4, 7, 2], [2, 7, 9], [0, 1, 3]])
    vertices, local_F = mesh.submesh(F, np.array([1, 0]))
    np.testing.assert_array_equal(vertices, [2, 4, 7, 9])
    np.testing.assert_array_equal(local_F, [[0, 2, 3], [1, 2, 0]])
    np.testing.assert_array_equal(vertices[local_F], F[[1, 0]])
    assert vertices.dtype == local_F.dtype == np.int64


def test_group_by_label_lists_each_label_in_index_order():
    labels = np.array([2, 0, 2, 2, 0, 3])
    order, bounds = mesh.group_by_label(labels, 5)
    groups = [order[bounds[k] : bounds[k + 1]].tolist() for k in range(5)]
    assert groups == [[1, 4], [], [0, 2, 3], [5], []]


def test_edges_of_int32_faces_past_46341_vertices():
    # the edge keys lo * n + hi overflow 32 bits from n = 46,341: they are built in int64
    n = 50_000
    F = np.array([[0, n - 1, n - 2], [1, n - 1, n - 2]], dtype=np.int32)
    E, h2e = mesh.edges(F)
    assert E.dtype == np.int64
    np.testing.assert_array_equal(
        E, [[0, n - 2], [0, n - 1], [1, n - 2], [1, n - 1], [n - 2, n - 1]]
    )
    np.testing.assert_array_equal(E[h2e], np.sort(mesh._half_edges(F), axis=1))


@pytest.mark.parametrize("holes", [True, False])
def test_disk_labels_fast_path_on_manifold_meshes_agrees_with_the_general_test(holes):
    # disk_labels(manifold_edges=...) reads each label's boundary half-edges; the general test
    # builds every label's own mesh. Label fields with disks, annuli (holes), bowtie vertices,
    # two-piece labels, a whole closed surface and a torus's bands.
    import trimesh

    from segparam.clean import clean

    rng = np.random.default_rng(0)
    surfaces = [tri_grid(12, 12), spherical_cap()]
    for m in (trimesh.creation.torus(2.0, 0.7, major_sections=24, minor_sections=12),
              trimesh.creation.icosphere(2)):  # fmt: skip
        surfaces.append((np.asarray(m.vertices), np.asarray(m.faces)))
    tested = disks = 0
    for V, F in surfaces:
        c = clean(V, F)
        F = c.F
        C = c.V[F].mean(axis=1)
        pairs, _ = mesh.face_adjacency(F)
        fields = [np.zeros(len(F), dtype=np.int64)]
        for k in (2, 5, 12, 40):  # blobs around random seed faces, nearest in 3-D
            seeds = C[rng.choice(len(F), k, replace=False)]
            fields.append(((C[:, None] - seeds[None]) ** 2).sum(axis=2).argmin(axis=1))
        for lab in list(fields[1:]):
            noisy = lab.copy()
            k = rng.choice(len(pairs), len(pairs) // 10)
            noisy[pairs[k, 0]] = noisy[pairs[k, 1]]  # islands, holes, bowties
            fields.append(noisy)
            merged = lab.copy()
            merged[merged == lab.max()] = 0  # two blobs as one label: two pieces or an annulus
            fields.append(merged)
        for lab in fields:
            lab = np.unique(lab, return_inverse=True)[1].ravel().astype(np.int64)
            n = int(lab.max()) + 1
            want = mesh.disk_labels(F, lab, n, holes=holes)
            got = mesh.disk_labels(F, lab, n, holes=holes, manifold_edges=mesh.edges(F))
            assert np.array_equal(got, want)
            tested += n
            disks += int(want.sum())
    assert tested > 500 and 0.2 < disks / tested < 0.9  # both answers well represented
    # A disk and a closed torus as one label: Euler characteristic 1 + 0 and one boundary loop,
    # as a disk has; only the count of pieces tells them apart.
    Vg, Fg = tri_grid(4, 4)
    Vt, Ft = surfaces[2]
    F = clean(np.vstack([Vg, Vt + 5.0]), np.vstack([Fg, Ft + len(Vg)])).F
    lab = np.zeros(len(F), dtype=np.int64)
    for manifold_edges in (None, mesh.edges(F)):
        assert not mesh.disk_labels(F, lab, 1, manifold_edges=manifold_edges)[0]


def test_face_cross_is_numpys_cross_bit_for_bit():
    rng = np.random.default_rng(7)
    for scale in (1e-9, 1.0, 1e12):
        V = rng.normal(size=(50, 3)) * scale + rng.normal(size=3) * scale * 10
        F = rng.integers(0, 50, size=(400, 3))
        want = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        got = mesh._face_cross(V, F)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()


def test_edges_ends_are_the_counts_and_first_and_last_half_edges():
    rng = np.random.default_rng(8)
    for F in [tri_grid(7, 5)[1], rng.integers(0, 12, size=(200, 3)), np.zeros((0, 3), int)]:
        E, h2e = mesh.edges(F)
        E2, h2e2, count, first, last = mesh.edges(F, ends=True)
        np.testing.assert_array_equal(E2, E)
        np.testing.assert_array_equal(h2e2, h2e)
        np.testing.assert_array_equal(count, np.bincount(h2e, minlength=len(E)))
        want_first, want_last = mesh.edge_half_edges(h2e, len(E))
        np.testing.assert_array_equal(first, want_first)
        np.testing.assert_array_equal(last, want_last)


def test_boundary_pieces_are_the_loops():
    """``boundary_pieces``: a square grid has one boundary loop, the grid with its middle cell
    removed two; every boundary vertex gets its loop, ``idx`` indexes ``verts``."""
    from segparam.mesh import boundary_edges, boundary_pieces

    i, j = (a.ravel() for a in np.meshgrid(np.arange(3), np.arange(3), indexing="ij"))
    v = 4 * i + j
    quads = np.stack([v, v + 4, v + 5, v + 1], 1)
    for keep, expected in ((np.ones(9, dtype=bool), 1), (np.arange(9) != 4, 2)):
        q = quads[keep]
        F = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        B = boundary_edges(F)
        verts, idx, n, piece = boundary_pieces(B)
        assert n == expected
        assert np.array_equal(verts[idx], B)
        assert len(np.unique(piece)) == expected and len(piece) == len(verts)


def test_an_annulus_cut_open_along_its_shortest_path_is_a_disk():
    """``annulus_cut``: the shortest edge path from one loop of a tube to the other (straight up
    a side); ``cut_along`` it: one loop, Euler characteristic 1, each vertex of the path twice,
    the faces on copies of their own vertices. A disk has no such cut."""
    n_theta, n_z = 16, 5
    theta = 2 * np.pi * np.arange(n_theta) / n_theta
    z = np.linspace(0.0, 2.0, n_z)  # ring spacing 0.5, longer than the ring's edges (0.39)
    V = np.stack([np.cos(theta)[None].repeat(n_z, 0), np.sin(theta)[None].repeat(n_z, 0),
                  z[:, None].repeat(n_theta, 1)], -1).reshape(-1, 3)  # fmt: skip
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n_z - 1), np.arange(n_theta), indexing="ij"))
    a, b = i * n_theta + j, i * n_theta + (j + 1) % n_theta
    F = np.concatenate(
        [np.stack([a, b, b + n_theta], 1), np.stack([a, b + n_theta, a + n_theta], 1)]
    )
    cut = mesh.annulus_cut(V, F)
    assert len(cut) == n_z - 1
    assert np.allclose(np.linalg.norm(V[cut[:, 0]] - V[cut[:, 1]], axis=1), 0.5)
    ends = np.setdiff1d(cut.ravel(), np.intersect1d(cut[:, 0], cut[:, 1]))
    assert sorted(V[ends, 2].tolist()) == [0.0, 2.0]  # one end on each loop
    F_cut, src = mesh.cut_along(F, cut)
    assert np.array_equal(src[F_cut], F)
    assert len(src) == len(V) + n_z and len(mesh.boundary_loops(F_cut)) == 1
    assert mesh.euler_characteristic(F_cut) == 1 and mesh.is_disk(F_cut, holes=False)
    assert np.array_equal(np.bincount(src, minlength=len(V)) == 2, np.isin(np.arange(len(V)), cut))
    # uncut: the same mesh; a disk: no cut
    F_same, src_same = mesh.cut_along(F, np.zeros((0, 2), dtype=np.int64))
    assert np.array_equal(src_same[F_same], F) and len(src_same) == len(V)
    Vd, Fd = tri_grid(5, 5)
    assert mesh.annulus_cut(Vd, Fd).shape == (0, 2)


@settings(max_examples=30, deadline=None)
@given(
    n_around=st.integers(3, 24),
    n_along=st.integers(1, 6),
    r_top=st.floats(0.2, 2.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_any_tube_cut_open_is_a_disk(n_around, n_along, r_top, seed):
    """Tubes of any size, down to one row and three sides, cones included, their vertices
    jittered: the cut runs from loop to loop, and the mesh cut along it is a disk on copies of
    its vertices, each vertex of the cut twice."""
    rng = np.random.default_rng(seed)
    t = 2 * np.pi * np.arange(n_around) / n_around
    z = np.linspace(0.0, 1.0, n_along + 1)
    r = 1.0 + (r_top - 1.0) * z
    V = np.stack(
        [np.outer(r, np.cos(t)), np.outer(r, np.sin(t)), np.repeat(z[:, None], n_around, 1)], -1
    ).reshape(-1, 3)
    V += 0.02 * rng.uniform(-1, 1, V.shape)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n_along), np.arange(n_around), indexing="ij"))
    a, b = i * n_around + j, i * n_around + (j + 1) % n_around
    F = np.concatenate(
        [np.stack([a, b, b + n_around], 1), np.stack([a, b + n_around, a + n_around], 1)]
    )
    cut = mesh.annulus_cut(V, F)
    assert len(cut) >= 1 and len(np.unique(cut)) == len(cut) + 1  # a simple path
    F_cut, src = mesh.cut_along(F, cut)
    assert np.array_equal(src[F_cut], F)
    assert mesh.euler_characteristic(F_cut) == 1 and len(mesh.boundary_loops(F_cut)) == 1
    assert np.array_equal(np.bincount(src, minlength=len(V)) == 2, np.isin(np.arange(len(V)), cut))


def test_vertex_components_join_faces_through_a_shared_vertex():
    from segparam.mesh import connected_components

    # a bow tie (two triangles touching at vertex 2), then a triangle apart, listed first
    F = np.array([[5, 6, 7], [0, 1, 2], [2, 3, 4]])
    assert connected_components(F, by="vertex")[0] == 2
    np.testing.assert_array_equal(connected_components(F, by="vertex")[1], [0, 1, 1])
    count, edge = connected_components(F, by="edge")  # no side shared: three
    assert count == 3 and edge[1] != edge[2]


def test_curvature_shares_hold_the_curvature_of_every_region_whatever_the_mesh():
    import trimesh

    from segparam.mesh import curvature_shares, inner_curvature

    for subdivisions in (1, 3):
        m = trimesh.creation.icosphere(subdivisions)
        V, F = np.asarray(m.vertices), np.asarray(m.faces)
        share = curvature_shares(V, F)
        assert share.sum() == pytest.approx(4 * np.pi)  # Gauss-Bonnet, closed genus 0
        upper = V[F].mean(axis=1)[:, 2] > 0
        # Half the sphere's faces hold about the solid angle they cover (Van Oosterom and
        # Strackee's formula) even on 80 faces, where the half's inner vertices hold much less:
        # the vertices of the cut are inner to the sphere but on the half's border.
        a, b, c = V[F[upper]].transpose(1, 0, 2)
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        dots = 1 + (a * b).sum(1) + (b * c).sum(1) + (c * a).sum(1)
        solid_angle = 2 * np.arctan2(det, dots).sum()
        assert share[upper].sum() == pytest.approx(solid_angle, rel=0.1)
        used = np.unique(F[upper])
        remap = np.full(len(V), -1)
        remap[used] = np.arange(len(used))
        net, absolute = inner_curvature(V[used], remap[F[upper]], np.zeros(len(used), int), 1)
        assert 0 < net[0] < share[upper].sum() and absolute[0] == pytest.approx(net[0])
    V, F = tri_grid(6, 6)  # flat: its boundary turns, it holds no curvature
    assert np.allclose(curvature_shares(V, F), 0, atol=1e-12)


def test_a_slit_runs_from_the_innermost_vertex_to_the_nearest_rim_vertex():
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    V, F = tri_grid(9, 7)
    cut = mesh.slit_cut(V, F)
    E = mesh.edges(F)[0]
    assert {tuple(e) for e in np.sort(cut, axis=1).tolist()} <= {tuple(e) for e in E.tolist()}
    # a simple path: its ends are the vertices used once
    ends = np.flatnonzero(np.bincount(cut.ravel(), minlength=len(V)) == 1)
    rim = np.unique(mesh.boundary_edges(F))
    assert len(ends) == 2 and np.isin(ends, rim).sum() == 1
    assert np.isin(np.setdiff1d(cut.ravel(), ends), rim).sum() == 0  # only one end on the rim
    # brute force: every vertex's distance to the rim along the edges
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])))
    to_rim = dijkstra(G.tocsr(), indices=rim, min_only=True)
    inner = ends[~np.isin(ends, rim)][0]
    assert to_rim[inner] == pytest.approx(to_rim.max())  # the innermost vertex
    length = np.linalg.norm(V[cut[:, 0]] - V[cut[:, 1]], axis=1).sum()
    assert length == pytest.approx(to_rim[inner])  # and the shortest way out
    assert mesh.slit_cut(V, F[:1]).shape == (0, 2)  # one triangle: no inner vertex


def test_cotan_laplacian_is_symmetric_semidefinite_and_exact_on_linear_functions():
    # The finite-element stiffness matrix: symmetric, rows summing to 0, positive semi-definite
    # (obtuse corners included: a jittered grid), and linear functions on a planar mesh are
    # harmonic at its inner vertices (the cotangent formula's linear precision).
    V, F = tri_grid(9, 8)
    rng = np.random.default_rng(3)
    V[:, :2] += rng.uniform(-0.03, 0.03, (len(V), 2))
    L = mesh.cotan_laplacian(V, F)
    dense = L.toarray()
    assert np.allclose(dense, dense.T, atol=0) and np.abs(dense.sum(axis=1)).max() < 1e-12
    assert np.linalg.eigvalsh(dense).min() > -1e-12
    assert (mesh.corner_angles(V, F) > np.pi / 2).any()  # some obtuse corners
    inner = np.ones(len(V), dtype=bool)
    inner[mesh.boundary_edges(F).ravel()] = False
    for f in (V[:, 0], V[:, 1], 2 * V[:, 0] - 3 * V[:, 1] + 1):
        assert np.abs((L @ f)[inner]).max() < 1e-12
    # the inner vertices' rows and columns alone: the same entries, the boundary's dropped
    L_in = mesh.cotan_laplacian(V, F, keep=inner).toarray()
    assert np.array_equal(L_in, dense[inner][:, inner])
    # one triangle: each edge's weight is half the cotangent of the corner opposite it
    V1 = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    L1 = mesh.cotan_laplacian(V1, np.array([[0, 1, 2]])).toarray()
    # the corner at vertex 0 is a right angle: edge 1-2 gets 0; at vertex 1, cot = 2, edge 0-2
    assert L1[1, 2] == pytest.approx(0.0, abs=1e-12)
    assert L1[0, 2] == pytest.approx(-0.5 * 2.0) and L1[0, 1] == pytest.approx(-0.5 * 0.5)


def test_interior_vertices_are_the_used_ones_off_the_boundary():
    # a grid with one unused vertex appended: its rim and the unused vertex are not interior,
    # and the interior defect is zero exactly off that mask
    V, F = tri_grid(5, 4)
    V = np.vstack([np.c_[V[:, :2], 0.1 * np.sin(V[:, 0] * 3)], [[9.0, 9.0, 9.0]]])
    inner = mesh.interior_vertices(F, len(V))
    rim = np.unique(mesh.boundary_edges(F))
    used = np.zeros(len(V), dtype=bool)
    used[F.ravel()] = True
    assert np.array_equal(inner, used & ~np.isin(np.arange(len(V)), rim))
    assert inner.sum() == len(V) - 1 - len(rim) > 0
    defect, _ = mesh.interior_defect(V, F)
    assert np.array_equal(defect, mesh.interior_defect(V, F, interior=inner)[0])
    assert (defect[~inner] == 0).all()


def test_cone_slits_free_each_charts_strongest_cone_by_the_shortest_way_out():
    # Two charts in one union: a flat grid with one vertex raised (a cone) and a flat grid
    # (none). The first's slit runs from its apex, the strongest cone, to its nearest rim
    # vertex, as far as a brute-force search says; the flat one gets none.
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    V, F = tri_grid(7, 6)
    V = np.c_[V[:, :2], np.zeros(len(V))]
    apex = int(np.argmin(((V[:, :2] - [0.45, 0.4]) ** 2).sum(axis=1)))
    V[apex, 2] = 0.1
    V[apex - 1, 2] = 0.02  # a weaker cone beside it
    n = len(V)
    Vu, Fu = np.r_[V, V * [1, 1, 0]], np.r_[F, F + n]
    vert_chart = np.repeat([0, 1], n)
    slits, defect = mesh.cone_slits(Vu, Fu, vert_chart, 2)
    strength = np.abs(mesh.interior_defect(V, F)[0])
    assert int(np.argmax(strength)) == apex and defect[0] == strength[apex] and defect[1] == 0
    assert slits[1].shape == (0, 2)
    cut = slits[0]
    E = mesh.edges(F)[0]
    assert {tuple(e) for e in np.sort(cut, axis=1).tolist()} <= {tuple(e) for e in E.tolist()}
    ends = np.flatnonzero(np.bincount(cut.ravel(), minlength=n) == 1)
    rim = np.unique(mesh.boundary_edges(F))
    assert apex in ends and np.isin(np.setdiff1d(ends, [apex]), rim).all()
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])))
    to_rim = dijkstra(G.tocsr(), indices=rim, min_only=True)
    length = np.linalg.norm(V[cut[:, 0]] - V[cut[:, 1]], axis=1).sum()
    assert length == pytest.approx(to_rim[apex])
    # a bound above the apex's defect: no slit at all
    slits, defect = mesh.cone_slits(Vu, Fu, vert_chart, 2, min_defect=strength[apex] + 1e-9)
    assert all(len(s) == 0 for s in slits) and not defect.any()
    # a saddle's vertices have negative defects: a slit's sides would overlap in the plane
    from meshes import saddle

    V, F = saddle(8, 8)
    assert (mesh.interior_defect(V, F)[0] < -1e-3).sum() > 10
    slits, defect = mesh.cone_slits(V, F, np.zeros(len(V), dtype=np.int64), 1)
    assert len(slits[0]) == 0 and defect[0] == 0
