"""A self-contained HTML viewer of a textured atlas (``<stem>.html``).

One file that works when opened from disk with no network: the mesh (split along seams, as in
the OBJ/GLB), its normals and uvs as base64 float32/uint32 arrays, every texture as a PNG data
URI, and about a hundred lines of WebGL 1 written here (no library, no CDN). Drag to rotate,
wheel to zoom, a menu switches between the textures (checker, each baked texture,
the uv layout); the current texture is also shown flat beside the model.

The page records its own state for tests and users: ``document.body.dataset.state`` becomes
``"ready"`` after the first frame with a texture, and any JavaScript error or WebGL failure is
written into the ``#errors`` element (and the state becomes ``"error"``).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
from collections.abc import Mapping

import numpy as np

__all__ = ["viewer_html", "write_viewer"]


def _png_data_uri(image) -> str:
    """A PNG data URI of PNG bytes or an (h, w, 3) uint8 array."""
    if isinstance(image, (bytes, bytearray)):
        data = bytes(image)
    else:
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(buf, format="PNG")
        data = buf.getvalue()
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _b64(a: np.ndarray, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def viewer_html(
    V: np.ndarray,
    F: np.ndarray,
    uv: np.ndarray,
    face_uv: np.ndarray,
    textures: Mapping[str, object],
    *,
    title: str = "segparam atlas",
) -> str:
    """The viewer page as a string.

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int ndarrays
        The atlas mesh.
    uv, face_uv : (k, 2) float, (m, 3) int ndarrays
        Texture coordinates (origin bottom-left) and the uv row of every face corner; the page
        draws one vertex per uv row (positions ``V`` of the mesh vertex at that corner).
    textures : mapping name -> PNG bytes or (h, w, 3) uint8 array (picture order)
        In menu order; the first is shown at start.
    title : str
    """
    from .mesh import vertex_normals

    if not textures:
        raise ValueError("the viewer needs at least one texture")
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    face_uv = np.asarray(face_uv, dtype=np.int64).reshape(-1, 3)
    uv_vertex = np.zeros(len(uv), dtype=np.int64)
    uv_vertex[face_uv.ravel()] = F.ravel()
    # centred and scaled to the unit sphere here, in float64, so float32 keeps the detail
    centre = (V.min(axis=0) + V.max(axis=0)) / 2
    radius = float(np.sqrt(((V - centre) ** 2).sum(axis=1).max())) or 1.0
    P = (V[uv_vertex] - centre) / radius
    N = vertex_normals(V, F, weighting="area")[uv_vertex]
    mesh = {
        "positions": _b64(P, "<f4"),
        "normals": _b64(N, "<f4"),
        "uvs": _b64(uv, "<f4"),
        "indices": _b64(face_uv, "<u4"),
        "vertices": int(len(uv)),
    }
    tex = [{"name": str(k), "src": _png_data_uri(v)} for k, v in textures.items()]
    data = json.dumps({"mesh": mesh, "textures": tex}, separators=(",", ":"))
    return (
        _TEMPLATE.replace("%TITLE%", html.escape(title))
        .replace("%DATA%", data.replace("</", "<\\/"))
        .replace("%SCRIPT%", _SCRIPT)
    )


def write_viewer(path: str | os.PathLike, *args, **kwargs) -> None:
    """Write :func:`viewer_html` (same arguments) to ``path`` (``<stem>.html``, UTF-8)."""
    text = viewer_html(*args, **kwargs)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)


_TEMPLATE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>%TITLE%</title>
<style>
html, body { margin: 0; height: 100%; font: 14px sans-serif; background: #fafafa; }
body { display: flex; flex-direction: column; }
header { padding: 6px 10px; display: flex; gap: 12px; align-items: center; }
main { flex: 1; display: flex; min-height: 0; }
#view { flex: 1; min-width: 0; touch-action: none; cursor: grab; }
#flat { width: 40%; height: 100%; object-fit: contain; border-left: 1px solid #ddd; }
#errors { color: #b00; margin: 0 10px; white-space: pre-wrap; }
</style></head>
<body data-state="loading">
<header><strong>%TITLE%</strong>
<label>texture <select id="texture"></select></label>
<label><input type="checkbox" id="showflat" checked> flat</label>
<span>drag: rotate, wheel: zoom</span></header>
<pre id="errors"></pre>
<main><canvas id="view"></canvas><img id="flat" alt="the texture, flat"></main>
<script id="atlas-data" type="application/json">%DATA%</script>
<script>
%SCRIPT%
</script>
</body></html>
"""

_SCRIPT = r"""
"use strict";
const errorsEl = document.getElementById("errors");
function fail(message) {
  console.error(message);
  errorsEl.textContent += message + "\n";
  document.body.dataset.state = "error";
}
window.addEventListener("error", (e) => {
  errorsEl.textContent += "error: " + e.message + "\n";
  document.body.dataset.state = "error";
});
const DATA = JSON.parse(document.getElementById("atlas-data").textContent);

function decode(b64, Type) {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  return new Type(bytes.buffer);
}

const canvas = document.getElementById("view");
const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
if (!gl) throw new Error("WebGL is not available in this browser");
if (!gl.getExtension("OES_element_index_uint")) throw new Error("WebGL lacks 32-bit indices");

const VS = `attribute vec3 p; attribute vec3 n; attribute vec2 t;
uniform mat4 mv; uniform mat4 proj; varying vec2 vt; varying vec3 vn;
void main() { vt = t; vn = (mv * vec4(n, 0.0)).xyz; gl_Position = proj * mv * vec4(p, 1.0); }`;
const FS = `precision mediump float; uniform sampler2D tex; varying vec2 vt; varying vec3 vn;
void main() {
  float l = 0.35 + 0.65 * abs(normalize(vn).z);   // headlight, both sides lit
  gl_FragColor = vec4(texture2D(tex, vec2(vt.x, 1.0 - vt.y)).rgb * l, 1.0);
}`;
function shader(type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}
const prog = gl.createProgram();
gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS));
gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS));
gl.linkProgram(prog);
if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
gl.useProgram(prog);

function attribute(name, array, size) {
  const b = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, b);
  gl.bufferData(gl.ARRAY_BUFFER, array, gl.STATIC_DRAW);
  const loc = gl.getAttribLocation(prog, name);
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
}
const M = DATA.mesh;
attribute("p", decode(M.positions, Float32Array), 3);
attribute("n", decode(M.normals, Float32Array), 3);
attribute("t", decode(M.uvs, Float32Array), 2);
const indices = decode(M.indices, Uint32Array);
gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, indices, gl.STATIC_DRAW);
gl.enable(gl.DEPTH_TEST);

// column-major 4x4 matrices
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), d = near - far;
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / d, -1, 0, 0, 2 * far * near / d, 0];
}
function multiply(a, b) {
  const o = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) for (let k = 0; k < 4; k++)
    o[c * 4 + r] += a[k * 4 + r] * b[c * 4 + k];
  return o;
}
function rotation(yaw, pitch) {
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const Ry = [cy, 0, -sy, 0, 0, 1, 0, 0, sy, 0, cy, 0, 0, 0, 0, 1];
  const Rx = [1, 0, 0, 0, 0, cp, sp, 0, 0, -sp, cp, 0, 0, 0, 0, 1];
  return multiply(Rx, Ry);
}
const view = { yaw: -0.5, pitch: 0.35, distance: 3.2 };

const textures = [];
let current = 0;
const ready = [];
const select = document.getElementById("texture");
const flat = document.getElementById("flat");
DATA.textures.forEach((t, i) => {
  const opt = document.createElement("option");
  opt.value = i; opt.textContent = t.name; select.appendChild(opt);
  const tex = gl.createTexture();
  textures.push(tex);
  const img = new Image();
  img.onload = () => {
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB, gl.RGB, gl.UNSIGNED_BYTE, img);
    const pot = (img.width & (img.width - 1)) === 0 && (img.height & (img.height - 1)) === 0;
    if (pot) {
      gl.generateMipmap(gl.TEXTURE_2D);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
    } else {
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    }
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    ready[i] = true;
    draw();
  };
  img.onerror = () => fail("cannot decode texture " + t.name);
  img.src = t.src;
});
select.addEventListener("change", () => { current = +select.value; show(); });
document.getElementById("showflat").addEventListener("change", (e) => {
  flat.style.display = e.target.checked ? "" : "none"; resize();
});
function show() { flat.src = DATA.textures[current].src; draw(); }

function resize() {
  const dpr = window.devicePixelRatio || 1;
  canvas.width = Math.max(1, Math.round(canvas.clientWidth * dpr));
  canvas.height = Math.max(1, Math.round(canvas.clientHeight * dpr));
  draw();
}
function draw() {
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.98, 0.98, 0.98, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!ready[current]) return;
  const mv = multiply([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, -view.distance, 1],
                      rotation(view.yaw, view.pitch));
  const proj = perspective(0.7, canvas.width / canvas.height, 0.05, 100);
  gl.uniformMatrix4fv(gl.getUniformLocation(prog, "mv"), false, mv);
  gl.uniformMatrix4fv(gl.getUniformLocation(prog, "proj"), false, proj);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, textures[current]);
  gl.uniform1i(gl.getUniformLocation(prog, "tex"), 0);
  gl.drawElements(gl.TRIANGLES, indices.length, gl.UNSIGNED_INT, 0);
  const err = gl.getError();
  if (err !== gl.NO_ERROR) fail("WebGL error " + err);
  else if (document.body.dataset.state === "loading") document.body.dataset.state = "ready";
}

let drag = null;
canvas.addEventListener("pointerdown", (e) => {
  drag = { x: e.clientX, y: e.clientY }; canvas.setPointerCapture(e.pointerId);
});
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  view.yaw += (e.clientX - drag.x) * 0.01;
  view.pitch = Math.max(-1.55, Math.min(1.55, view.pitch + (e.clientY - drag.y) * 0.01));
  drag = { x: e.clientX, y: e.clientY };
  draw();
});
canvas.addEventListener("pointerup", () => { drag = null; });
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  view.distance = Math.max(1.2, Math.min(20, view.distance * Math.exp(e.deltaY * 0.001)));
  draw();
}, { passive: false });
window.addEventListener("resize", resize);
show();
resize();
"""
