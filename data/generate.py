"""Regenerate the sample meshes in this folder: ``python data/generate.py``.

Deterministic: the same segparam version writes the same bytes.
"""

from __future__ import annotations

from pathlib import Path

from segparam.export import write_obj
from segparam.synthetic import brain_like_parcels, brain_like_surface

HERE = Path(__file__).resolve().parent


def main() -> None:
    parcels = brain_like_parcels(12, mean_faces=1850, min_faces=1000, max_faces=2500, seed=7)
    V, F = max(parcels, key=lambda p: len(p[1]))
    write_obj(HERE / "brain_parcel.obj", V, F)
    # The quick start's default mesh: a closed, folded hemisphere of 20k faces.
    V, F = brain_like_surface(20_000, seed=1)
    write_obj(HERE / "brain.obj", V, F)


if __name__ == "__main__":
    main()
