"""The self-contained HTML viewer (segparam.viewer), in a real headless browser."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest
from test_bake import cube_atlas

from segparam.bake import bake
from segparam.viewer import viewer_html, write_viewer

SIDE_COLOURS = np.array(
    [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [0, 255, 255], [255, 0, 255]]
)


def cube_page(tmp_path, **kwargs):
    V, F, uv = cube_atlas()
    image, _ = bake(V, F, uv, F, np.repeat(SIDE_COLOURS / 255, 4, axis=0), 64)
    texture = np.round(image * 255).astype(np.uint8)
    grey = np.full((8, 8, 3), 128, dtype=np.uint8)
    path = tmp_path / "cube.html"
    write_viewer(path, V, F, uv, F, {"sides": texture, "grey": grey}, **kwargs)
    return path


def test_page_is_self_contained(tmp_path):
    text = cube_page(tmp_path, title="a <cube>").read_text(encoding="utf-8")
    # nothing fetched from anywhere: no URL but data URIs, no external script or stylesheet
    assert not re.search(r"https?://", text)
    assert not re.search(r"<script[^>]+src=", text)
    assert not re.search(r"<link[^>]+href=", text)
    assert text.count("data:image/png;base64,") == 2
    assert "a &lt;cube&gt;" in text  # the title is escaped
    assert ">sides<" not in text  # menu entries come from the data, not the markup
    assert '"name":"sides"' in text and '"name":"grey"' in text


def test_needs_a_texture():
    V, F, uv = cube_atlas()
    with pytest.raises(ValueError, match="texture"):
        viewer_html(V, F, uv, F, {})


def _browser() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


# ~3 s on this machine (chromium's start-up), not marked slow so that CI (.ci/run) runs it
def test_viewer_in_headless_chromium(tmp_path):
    browser = _browser()
    if browser is None:
        pytest.skip("no chromium: install Debian's chromium package (.ci/run does)")
    page = cube_page(tmp_path)
    shot = tmp_path / "shot.png"
    run = subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",  # software WebGL: no GPU needed
            "--enable-unsafe-swiftshader",
            "--window-size=800,600",
            "--virtual-time-budget=1000",  # wait for the textures to decode
            "--enable-logging=stderr",
            "--v=0",
            f"--user-data-dir={tmp_path / 'profile'}",
            f"--screenshot={shot}",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert shot.exists(), run.stderr[-2000:]
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
    assert console == [], console  # the page logs nothing unless something failed
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    canvas = img[40:, : int(0.6 * img.shape[1])]  # the 3-D view, left of the flat texture
    # the cube's visible sides are drawn in their (shaded) colours: pure hues, scaled
    sides_seen = 0
    for colour in SIDE_COLOURS:
        on = colour > 0
        lit = canvas[..., on].min(axis=-1)
        off = canvas[..., ~on].max(axis=-1) if (~on).any() else np.zeros(lit.shape)
        share = np.mean((lit > 60) & (off < 0.25 * lit))
        sides_seen += share > 0.01
    assert sides_seen >= 2, sides_seen  # at least two sides from any viewpoint
    background = np.all(canvas == canvas[5, 5], axis=-1).mean()
    assert 0.2 < background < 0.97
