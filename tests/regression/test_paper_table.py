"""The paper's comparison as a regression suite (section 4: the segmented Brain dataset).

On synthetic cortex-like parcels (folded hemisphere cut like atlas regions, then remeshed as the
paper's parcels were), the single-pass bijective rate of the raw eigenmaps must keep the paper's
ordering: averaged-normal tangents beat classic HLLE; the floors are set from measurements
(BENCHMARKS.md) a few charts below what was measured, so a regression fails them.

The fast subset (the first 12 parcels) runs by default; all 89 run with ``pytest -m full``.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from segparam.parameterize import parameterize_chart
from segparam.remesh import RemeshConfig, remesh
from segparam.synthetic import brain_like_parcels


@functools.lru_cache(maxsize=1)
def _raw_parcels() -> tuple:
    return tuple(
        brain_like_parcels(89, mean_faces=500, min_faces=250, max_faces=1000, folding=2.0, seed=0)
    )


def parcels(n: int) -> tuple:
    """The first ``n`` of the 89 parcels, remeshed (the paper remeshed its sub-meshes)."""
    out = []
    for V, F in _raw_parcels()[:n]:
        r = remesh(V, F, config=RemeshConfig(mode="on"))
        out.append((r.V, r.F))
    return tuple(out)


def rates(charts, **options) -> tuple[int, float]:
    results = [parameterize_chart(V, F, **options) for V, F in charts]
    ok = sum(r.bijective for r in results)
    return ok, float(np.median([r.quality.angle_distortion for r in results]))


def check_table(charts, floors, *, with_pca=False):
    n = len(charts)
    normals, _ = rates(charts, refine="none")
    classic, _ = rates(charts, method="classic-hlle", refine="none")
    refined, median_ad = rates(charts)
    assert normals > classic  # the paper's ordering
    if with_pca:
        pca, _ = rates(charts, tangent="pca", refine="none")
        assert normals > pca  # averaged normals beat PCA tangents (paper, section 3.1)
    assert normals >= floors["normals"] * n
    assert refined >= floors["refined"] * n
    assert median_ad <= floors["median_angle_distortion"]


def test_paper_table_fast_subset():
    check_table(
        parcels(12),
        # measured: normals 9/12, classic 8/12, refined 12/12, median s1/s2 1.034
        {"normals": 0.65, "refined": 0.90, "median_angle_distortion": 1.10},
    )


@pytest.mark.full
def test_paper_table_full():
    check_table(
        parcels(89),
        # measured: normals 76/89, PCA 69, classic 50, refined 87/89, median s1/s2 1.031
        {"normals": 0.80, "refined": 0.95, "median_angle_distortion": 1.10},
        with_pca=True,
    )
