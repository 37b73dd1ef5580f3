"""``report.html``: one self-contained page a person opens to check a result.

The page holds everything inline (no network at view time): the input frames with the pushes
drawn over them (start to end, projected with the frame's camera), each frame's segmentation
with the result's own object ids and colours (``ipr_shapes.perception.output.palette``, as in
``completion.png``), an interactive 3-D view of the completed scene, each object's top
hypotheses with their probabilities, the per-stage timings and the method's settings
(``result.json``'s ``provenance`` and ``inference``, ``config.toml``).

The 3-D view tells what was seen from what was inferred: per object, the points frame 0's
camera saw of it (its depth pixels under the result's labels, back-projected) are drawn solid,
and its complete inferred shape translucent: the smooth surface ``ipr_shapes.export.surface``
rebuilds from the result's 5 mm voxels (at ``SURFACE_EDGE_VOXELS``, coarser than the export's:
a quarter of the time and triangles). It is a small hand-written WebGL 1 viewer
(docs/DESIGN_NOTES.md, "report.html draws its 3-D view with its own WebGL").

Inputs: a result folder (``result.json``, meshes, ``labels/``, ``config.toml``) and its scene
(the frames' RGB and depth, intrinsics and pushes). The result's ``world_from_camera`` is
authoritative: pushes are moved from the scene's world frame into the result's, so a scene
whose world frame is found again differently still lines up.

    ipr-shapes report RESULT [--scene SCENE] [-o FILE]     # or write_report(result_dir, scene)
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes.errors import IprError, ResultError, SceneError
from ipr_shapes.perception.output import label_png, overlay_image, palette
from ipr_shapes.result import Result, load_result
from ipr_shapes.scene import Frame, Scene, frames_digest, load_scene

REPORT_FILE = "report.html"
#: The result's label images: per frame, 0 = nothing of the result, k = result object k.
LABELS_DIR = "labels"
#: Triangle edge of the 3-D view's surfaces, in voxels (the export's is 1).
SURFACE_EDGE_VOXELS = 2.0
#: At most this many observed points in the 3-D view (all objects together).
MAX_POINTS = 12_000
#: Frames shown at most (the first ones), and the largest width they are shown at (px).
MAX_FRAMES = 16
MAX_IMAGE_WIDTH = 640
#: Hypotheses listed per object.
TOP_HYPOTHESES = 5
#: JPEG quality of the embedded pictures.
JPEG_QUALITY = 85


# --------------------------------------------------------------------------------------------
# The result's label images


def result_labels(labels: Sequence[np.ndarray], objects: Sequence[Any], ids: Sequence[int]):
    """Per frame, an (H, W) int32 image of the result's object ids (0 = none).

    ``labels``: the perception's tracked label images (``Perception.labels``); ``objects``:
    frame 0's partial objects after the occluded pieces were joined (``PartialObject`` with
    ``id`` and flat ``pixels``); ``ids``: the result's object ids. Every label value under a
    result object's frame-0 pixels takes its id in every frame (a joined piece takes the id of
    the object it was joined to); the rest, 0."""
    wanted = {int(i) for i in ids}
    frame0 = np.asarray(labels[0]).reshape(-1) if len(labels) else np.zeros(0, np.int64)
    top = max((int(np.max(image)) for image in labels if np.size(image)), default=0)
    table = np.zeros(top + 1, dtype=np.int32)
    for obj in objects:
        if int(obj.id) in wanted:
            values = np.unique(frame0[np.asarray(obj.pixels, np.int64)])
            table[values[values > 0]] = int(obj.id)
    return [table[np.asarray(image, np.int64)] for image in labels]


def result_label_files(label_images: Sequence[np.ndarray], frames: Sequence[Frame]) -> dict:
    """``labels/NNNNNN.png`` name -> PNG bytes (``label_png``) of each frame's result labels."""
    return {
        f"{LABELS_DIR}/{frame.index:06d}.png": label_png(image)
        for frame, image in zip(frames, label_images, strict=True)
    }


def read_result_labels(folder: Path, frames: Sequence[Frame]) -> list[np.ndarray] | None:
    """The result's label images of ``frames`` (None when the result has no ``labels/``, as
    results written before it); ResultError for one that is unreadable or of the wrong size."""
    from PIL import Image

    if not (folder / LABELS_DIR).is_dir():
        return None
    images = []
    for frame in frames:
        path = folder / LABELS_DIR / f"{frame.index:06d}.png"
        try:
            with Image.open(path) as picture:
                image = np.asarray(picture).astype(np.int32)
        except FileNotFoundError:
            raise ResultError(path, "label image is missing", "rerun ipr-shapes infer") from None
        except Exception as error:  # PIL raises many types on corrupt files
            raise ResultError(path, f"label image cannot be read ({error})") from None
        if image.shape != frame.shape:
            raise ResultError(
                path,
                f"label image is {image.shape[1]}x{image.shape[0]}, the scene's frame "
                f"{frame.index} is {frame.shape[1]}x{frame.shape[0]}",
                "pass the scene this result was made from (--scene)",
            )
        images.append(image)
    return images


# --------------------------------------------------------------------------------------------
# The page's content


@dataclass(frozen=True)
class ReportTiming:
    """Seconds spent making the page, by part (measured for docs/DESIGN_NOTES.md)."""

    surfaces_s: float
    pictures_s: float
    total_s: float


def _hex(colour: np.ndarray) -> str:
    return "#" + "".join(f"{int(c):02x}" for c in colour)


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


def _jpeg(image: Any) -> str:
    """A PIL image as a data URL (JPEG), at most ``MAX_IMAGE_WIDTH`` wide."""
    from PIL import Image

    if image.width > MAX_IMAGE_WIDTH:
        height = round(image.height * MAX_IMAGE_WIDTH / image.width)
        image = image.resize((MAX_IMAGE_WIDTH, height), Image.Resampling.LANCZOS)
    buffer = io.BytesIO()
    image.convert("RGB").save(buffer, format="JPEG", quality=JPEG_QUALITY)
    return "data:image/jpeg;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def _project(points_world: np.ndarray, frame: Frame, world_from_camera: np.ndarray):
    """(N, 2) pixel coordinates and (N,) depths (m) of world points in ``frame``'s camera."""
    camera_from_world = np.linalg.inv(world_from_camera)
    camera = points_world @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    z = camera[:, 2]
    pixels = camera @ np.asarray(frame.K, float).T
    return pixels[:, :2] / np.where(np.abs(z) > 1e-9, z, 1e-9)[:, None], z


def _draw_pushes(image: Any, pushes: Sequence[tuple[np.ndarray, np.ndarray]], frame, pose) -> int:
    """Draw each push (start, end in the result's world frame) on ``image`` as an arrow;
    returns how many were in front of the camera and drawn."""
    from PIL import ImageDraw

    draw = ImageDraw.Draw(image)
    width = max(2, image.width // 160)
    drawn = 0
    for start, end in pushes:
        pixels, depth = _project(np.stack([start, end]), frame, pose)
        if np.any(depth <= 0):
            continue
        (x0, y0), (x1, y1) = pixels
        angle = math.atan2(y1 - y0, x1 - x0)
        head = 4 * width + 6
        wings = [
            (x1 - head * math.cos(angle + s * 0.45), y1 - head * math.sin(angle + s * 0.45))
            for s in (-1, 1)
        ]
        for colour, grow in (((0, 0, 0), 2), ((255, 255, 255), 0)):
            draw.line([(x0, y0), (x1, y1)], fill=colour, width=width + grow)
            draw.polygon([(x1, y1), *wings], fill=colour, outline=colour)
            r = width + 2 + grow / 2
            draw.ellipse([x0 - r, y0 - r, x0 + r, y0 + r], fill=colour)
        drawn += 1
    return drawn


def _observed_points(frame: Frame, labels: np.ndarray, pose: np.ndarray, ids, rng):
    """Per object id, (N, 3) float32 world points frame 0's camera saw of it (at most
    ``MAX_POINTS`` in all, the same fraction of each object's)."""
    seen = (labels > 0) & (frame.depth_m > 0)
    total = int(seen.sum())
    keep = min(1.0, MAX_POINTS / total) if total else 1.0
    K = np.asarray(frame.K, float)
    out = {}
    for object_id in ids:
        rows, cols = np.nonzero(seen & (labels == object_id))
        if keep < 1.0 and rows.size:
            chosen = rng.random(rows.size) < keep
            rows, cols = rows[chosen], cols[chosen]
        z = frame.depth_m[rows, cols].astype(np.float64)
        camera = np.stack([(cols - K[0, 2]) * z / K[0, 0], (rows - K[1, 2]) * z / K[1, 1], z], 1)
        out[int(object_id)] = (camera @ pose[:3, :3].T + pose[:3, 3]).astype(np.float32)
    return out


def _surface(mesh: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """The 3-D view's surface of a best mesh: vertices (V, 3) float32, faces (F, 3) uint32 and
    the shape's volume (m^3) (the smooth surface of ``ipr_shapes.export.surface``; the mesh itself
    when it cannot be rebuilt)."""
    from ipr_shapes.export.surface import SurfaceConfig, smooth_surface

    try:
        surface = smooth_surface(mesh, SurfaceConfig(edge_voxels=SURFACE_EDGE_VOXELS))
        built, volume = surface.mesh, surface.voxel_volume_m3
    except ValueError:  # no volume or absurd size: show it as written
        built, volume = mesh, abs(float(mesh.volume))
    return (
        np.asarray(built.vertices, np.float32),
        np.asarray(built.faces, np.uint32),
        float(volume),
    )


def _volume(path: Path) -> float | None:
    """The enclosed volume (m^3) of a hypothesis mesh (closed, as ipr writes them: the signed
    tetrahedra sum, without trimesh's slower mass properties); None if unreadable."""
    from ipr_shapes.result import read_mesh

    try:
        mesh = read_mesh(path)
    except ResultError:
        return None
    corners = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    signed = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))
    return abs(float(signed.sum())) / 6.0


def _pushes_in_result_world(scene: Scene, result: Result):
    """Per push: (frame before, frame after, start (3,), end (3,)), the pusher centre's path
    in the result's world frame (module doc)."""
    moved = result.world_from_camera[0] @ np.linalg.inv(scene.frames[0].world_from_camera)
    out = []
    for push in scene.pushes:
        start = moved[:3, :3] @ push.start_m + moved[:3, 3]
        end = moved[:3, :3] @ push.end_m + moved[:3, 3]
        out.append((int(push.before_frame), int(push.after_frame), start, end))
    return out


def report_data(result: Result, scene: Scene) -> tuple[dict, ReportTiming]:
    """Everything the page shows, as JSON-ready data (arrays base64), and what it cost."""
    import time

    from PIL import Image

    started = time.perf_counter()
    frames = [frame for frame in scene.frames if frame.index in result.world_from_camera]
    if not frames or frames[0].index != 0:
        raise IprError(
            f"{scene.path}: the scene has no frame 0 of result {result.path} "
            "(fix: pass the scene the result was made from with --scene)"
        )
    labels = read_result_labels(result.path, frames)
    ids = [obj.id for obj in result.objects]
    colours = {object_id: palette([object_id])[0] for object_id in ids}
    pushes = _pushes_in_result_world(scene, result)

    pictures = []
    for number, frame in enumerate(frames[:MAX_FRAMES]):
        pose = result.world_from_camera[frame.index]
        image = Image.fromarray(np.asarray(frame.rgb, np.uint8))
        mine = [(start, end) for before, _, start, end in pushes if before == frame.index]
        drawn = _draw_pushes(image, mine, frame, pose)
        entry = {"frame": frame.index, "input": _jpeg(image), "pushes": len(mine)}
        entry["pushes_drawn"] = drawn
        if labels is not None:
            overlay = overlay_image(np.asarray(frame.rgb, np.uint8), labels[number], labels[number])
            entry["segmentation"] = _jpeg(overlay)
            entry["ids"] = sorted(int(i) for i in np.unique(labels[number]) if i > 0)
        pictures.append(entry)
    pictures_s = time.perf_counter() - started

    surfaces_started = time.perf_counter()
    points = (
        _observed_points(frames[0], labels[0], result.world_from_camera[0], ids,
                         np.random.default_rng(0))
        if labels is not None
        else {}
    )  # fmt: skip
    # result.json's further keys as ipr writes them; another writer's are shown only if alike.
    listed = result.extra.get("objects_summary")
    summary = {
        entry["object_id"]: entry
        for entry in (listed if isinstance(listed, list) else [])
        if isinstance(entry, dict) and isinstance(entry.get("object_id"), int)
    }
    objects = []
    for obj in result.objects:
        vertices, faces, volume = _surface(obj.load_mesh())
        ranked = sorted(obj.hypotheses, key=lambda h: -h.probability)
        hypotheses = [
            {
                "file": os.path.relpath(h.mesh_path, result.path),
                "probability": h.probability,
                "volume_m3": _volume(h.mesh_path),
            }
            for h in ranked[:TOP_HYPOTHESES]
        ]
        details = summary.get(obj.id, {})
        seen = points.get(obj.id, np.zeros((0, 3), np.float32))
        objects.append(
            {
                "id": obj.id,
                "colour": _hex(colours[obj.id]),
                "probability": obj.probability,
                "volume_m3": volume,
                "hypotheses_count": len(obj.hypotheses),
                "hypotheses": hypotheses,
                "inference": details.get("inference"),
                "carved": details.get("carved"),
                "vertices": _b64(vertices),
                "faces": _b64(faces),
                "points": _b64(seen),
                "points_count": len(seen),
            }
        )
    surfaces_s = time.perf_counter() - surfaces_started
    camera = result.world_from_camera[0][:3, 3]
    provenance = result.extra.get("provenance")
    provenance = provenance if isinstance(provenance, dict) else {}
    inference = result.extra.get("inference")
    # Only a file of the result's own folder is read (its name, not a path elsewhere).
    config_path = result.path / Path(str(provenance.get("config_file", "config.toml"))).name
    data = {
        "method": result.method,
        "scene": str(provenance.get("scene", scene.path)),
        "created": provenance.get("created_utc"),
        "frames": pictures,
        "frames_total": len(frames),
        "has_labels": labels is not None,
        "objects": objects,
        "pushes": [
            {"before": b, "after": a, "start": s.tolist(), "end": e.tolist()}
            for b, a, s, e in pushes
        ],
        "camera": camera.tolist(),
        "timing_s": result.timing_s,
        "provenance": provenance,
        "inference": inference if isinstance(inference, dict) else {},
        "config_toml": config_path.read_text(encoding="utf-8") if config_path.is_file() else None,
    }
    total = time.perf_counter() - started
    return data, ReportTiming(surfaces_s, pictures_s, total)


# --------------------------------------------------------------------------------------------
# The page


def report_html(result: Result, scene: Scene) -> str:
    """The page's HTML text (module doc) of a loaded result (with its meshes) and its scene."""
    data, _ = report_data(result, scene)
    return render_page(data)


def render_page(data: dict) -> str:
    """The page of ``report_data``'s data: the template with the data inlined."""
    payload = json.dumps(data, allow_nan=False, separators=(",", ":"))
    # Inside <script> only "</" could end the element early.
    payload = payload.replace("</", "<\\/")
    title = f"ipr result: {Path(data['scene']).name} ({data['method']})"
    return (
        _TEMPLATE.replace("%TITLE%", html.escape(title))
        .replace("%CSS%", _CSS)
        .replace("%JS%", _JS)
        .replace("%DATA%", payload)
    )


def write_report_into(folder: Path, scene: Scene) -> Path:
    """Write ``report.html`` into a result folder (``folder``, e.g. the staging folder of
    ``ipr_shapes.result.write_result``'s ``finish``); returns its path."""
    folder = Path(folder)
    page = report_html(load_result(folder), scene)
    path = folder / REPORT_FILE
    path.write_text(page, encoding="utf-8")
    return path


def scene_of_result(result: Result, scene_path: Path | str | None = None, up_camera=None):
    """The scene a result was made from: ``scene_path``, else the folder its provenance names;
    read on the frames its provenance lists (all when it lists none). IprError (one line,
    with the fix) when it names none, the folder is gone, or the folder's frames are not the
    ones the result was made from (missing, or another ``frames_digest``)."""
    provenance = result.extra.get("provenance")
    provenance = provenance if isinstance(provenance, dict) else {}
    source = result.path / "result.json"
    if scene_path is None:
        named = provenance.get("scene")
        if not isinstance(named, str) or not named:
            raise IprError(
                f"{source}: names no scene (no provenance) (fix: pass the scene with --scene SCENE)"
            )
        scene_path = Path(named)
        if not scene_path.is_dir():
            raise IprError(
                f"{scene_path}: the scene of result {result.path} is not there "
                "(fix: pass where it is now with --scene SCENE)"
            )
    listed = provenance.get("frames")
    frames = None
    if isinstance(listed, list) and listed and all(type(i) is int and i >= 0 for i in listed):
        frames = listed
    mismatch = (
        f"{scene_path}: is not the scene result {result.path} was made from"
        " ({}) (fix: pass the scene it was made from with --scene SCENE)"
    )
    try:
        scene = load_scene(scene_path, up_camera=up_camera, frames=frames)
    except SceneError as error:
        if frames is None or "chosen frames" not in error.problem:
            raise
        raise IprError(
            mismatch.format(f"it lacks frames {frames} the result was made from")
        ) from None
    recorded = provenance.get("frames_digest")
    if isinstance(recorded, str) and recorded != frames_digest(scene.frames):
        raise IprError(mismatch.format(f"its frames differ from the ones {source} records"))
    return scene


def write_report(
    result_path: Path | str,
    out: Path | str | None = None,
    *,
    scene: Scene | Path | str | None = None,
    up_camera: Sequence[float] | None = None,
    overwrite: bool = False,
) -> Path:
    """(Re)make a result's ``report.html`` (``ipr-shapes report``): by default RESULT/report.html
    (replaced), else ``out`` (an existing file only with ``overwrite``). ``scene``: a loaded
    scene or its folder (default: the one the result's provenance names). Written through a
    temporary file and a rename; nothing is written on error."""
    result = load_result(result_path)
    target = Path(out) if out is not None else result.path / REPORT_FILE
    if out is not None:
        if target.is_dir():
            raise IprError(f"{target}: is a folder (fix: give the report's file name)")
        if target.exists() and not overwrite:
            raise IprError(f"{target}: already exists (fix: choose another file or --overwrite)")
    if not isinstance(scene, Scene):
        scene = scene_of_result(result, scene, up_camera)
    page = report_html(result, scene)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        staging.write_text(page, encoding="utf-8")
        staging.replace(target)
    finally:
        staging.unlink(missing_ok=True)
    return target


_TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>%TITLE%</title>
<style>%CSS%</style>
</head>
<body>
<header><h1 id="title"></h1><p id="subtitle"></p></header>
<main>
<section id="scene3d"><h2>Completed scene</h2>
<div class="controls" id="controls"></div>
<div class="viewer"><canvas id="view" width="900" height="520"></canvas>
<p class="hint">Drag to rotate, wheel to zoom, shift-drag (or right-drag) to pan, double-click
to reset. Solid points: what frame 0's camera saw of each object. Translucent: the inferred
complete shape (hidden parts included). Black lines: the pushes.</p>
<p id="view-message" class="message" hidden></p></div>
</section>
<section id="objects"><h2>Objects and their top hypotheses</h2><div id="object-table"></div></section>
<section id="frames"><h2>Input frames and segmentation</h2>
<p class="hint">Left: each input frame with the pushes made after it (white arrow: start to end of
the pusher's centre). Right: the segmentation with the result's object ids and colours.</p>
<div id="frame-grid"></div></section>
<section id="timing"><h2>Timings</h2><div id="timing-table"></div></section>
<section id="settings"><h2>Settings and provenance</h2><div id="settings-body"></div></section>
</main>
<script type="application/json" id="ipr-data">%DATA%</script>
<script>%JS%</script>
</body>
</html>
"""

_CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1d1f23;
background:#fafafa}
header{background:#23262d;color:#f4f5f7;padding:14px 24px}header h1{margin:0;font-size:20px}
header p{margin:4px 0 0;color:#c5c8d0}main{padding:8px 24px 40px;max-width:1400px}
h2{font-size:17px;margin:26px 0 8px;border-bottom:1px solid #ddd;padding-bottom:4px}
.viewer{position:relative}canvas#view{width:100%;height:520px;display:block;background:#f4f5f7;
border:1px solid #ccc;border-radius:4px;cursor:grab;touch-action:none}
.hint{color:#555;font-size:12.5px;margin:6px 0}.message{color:#a00;font-weight:600}
.controls label{margin-right:14px;white-space:nowrap;font-size:13px}
.controls button{margin:0 6px 4px 0;font-size:12px}
.swatch{display:inline-block;width:12px;height:12px;border-radius:2px;margin-right:4px;
vertical-align:-1px;border:1px solid rgba(0,0,0,.3)}
table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ddd;padding:3px 8px;
text-align:left;vertical-align:top}th{background:#eef0f3}td.num{text-align:right;
font-variant-numeric:tabular-nums}
.bar{display:inline-block;height:10px;background:#4a78c2;vertical-align:middle;margin-right:6px}
#frame-grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(560px,1fr));gap:12px}
.pair{display:grid;grid-template-columns:1fr 1fr;gap:6px}
figure{margin:0;background:#fff;border:1px solid #ddd;border-radius:4px;padding:6px}
figure img{width:100%;display:block}figcaption{font-size:12.5px;color:#333;margin-top:4px}
pre{background:#fff;border:1px solid #ddd;padding:8px;overflow:auto;max-height:480px;
font-size:12px}details{margin:8px 0}
"""

_JS = r"""
"use strict";
(function () {
  const root = document.documentElement;
  const errors = [];
  function fail(message) {
    errors.push(String(message));
    root.dataset.iprErrors = JSON.stringify(errors);
  }
  window.addEventListener("error", (e) => fail(e.message));
  const D = JSON.parse(document.getElementById("ipr-data").textContent);
  const el = (tag, attrs, ...children) => {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k === "text") node.textContent = v; else node.setAttribute(k, v);
    }
    for (const child of children) node.append(child);
    return node;
  };
  const fmt = (x, digits) => (x === null || x === undefined) ? "-" : Number(x).toFixed(digits);
  const cm3 = (m3) => (m3 === null || m3 === undefined) ? "-" : (m3 * 1e6).toFixed(0) + " cm\u00b3";
  const swatch = (colour) => el("span", {class: "swatch", style: "background:" + colour});

  // ---- header
  const sceneName = D.scene.split(/[\\/]/).filter(Boolean).pop() || D.scene;
  document.getElementById("title").textContent = "ipr result: " + sceneName;
  const count = (n, word) => n + " " + word + (n === 1 ? "" : (word.endsWith("sh") ? "es" : "s"));
  document.getElementById("subtitle").textContent = D.method + " \u2022 " +
    count(D.objects.length, "object") + " \u2022 " + count(D.frames_total, "frame") + " \u2022 " +
    count(D.pushes.length, "push") +
    (D.created ? " \u2022 " + D.created : "") + " \u2022 scene " + D.scene;

  // ---- objects table
  (function objectTable() {
    const table = el("table", {});
    table.append(el("tr", {}, ...["object", "p(best)", "volume", "how", "hypotheses (top, by probability)"]
      .map((t) => el("th", {text: t}))));
    for (const o of D.objects) {
      const hyps = el("table", {});
      for (const h of o.hypotheses) {
        hyps.append(el("tr", {},
          el("td", {class: "num", text: fmt(h.probability, 3)}),
          el("td", {}, el("span", {class: "bar", style: "width:" + Math.round(120 * h.probability) + "px"})),
          el("td", {class: "num", text: cm3(h.volume_m3)}),
          el("td", {text: h.file})));
      }
      const more = o.hypotheses_count - o.hypotheses.length;
      const cell = el("td", {}, hyps);
      if (more > 0) cell.append(el("div", {class: "hint", text: "and " + more + " more"}));
      const how = [o.inference, o.carved ? "carved" : (o.carved === false ? "not carved" : null)]
        .filter(Boolean).join(", ");
      table.append(el("tr", {},
        el("td", {}, swatch(o.colour), document.createTextNode(String(o.id))),
        el("td", {class: "num", text: fmt(o.probability, 3)}),
        el("td", {class: "num", text: cm3(o.volume_m3)}),
        el("td", {text: how || "-"}), cell));
    }
    document.getElementById("object-table").append(D.objects.length ? table :
      el("p", {text: "The result has no objects."}));
  })();

  // ---- frames
  (function frameGrid() {
    const grid = document.getElementById("frame-grid");
    for (const f of D.frames) {
      const pushes = f.pushes ? " \u2022 " + f.pushes + " push" + (f.pushes > 1 ? "es" : "") +
        " after it" + (f.pushes_drawn < f.pushes ? " (" + (f.pushes - f.pushes_drawn) + " behind the camera)" : "") : "";
      const pair = el("div", {class: "pair"}, el("img", {src: f.input, alt: "frame " + f.frame}));
      let caption = "frame " + f.frame + pushes;
      if (f.segmentation) {
        pair.append(el("img", {src: f.segmentation, alt: "segmentation of frame " + f.frame}));
        caption += " \u2022 segmented objects " + (f.ids.length ? f.ids.join(", ") : "none");
      }
      grid.append(el("figure", {}, pair, el("figcaption", {text: caption})));
    }
    if (D.frames_total > D.frames.length) {
      grid.append(el("p", {class: "hint", text: (D.frames_total - D.frames.length) + " more frames not shown"}));
    }
    if (!D.has_labels) {
      grid.append(el("p", {class: "hint", text: "This result has no labels/ folder: no segmentation to show."}));
    }
  })();

  // ---- timings
  (function timingTable() {
    const entries = Object.entries(D.timing_s);
    const longest = Math.max(1e-9, ...entries.map(([, v]) => v));
    const table = el("table", {});
    table.append(el("tr", {}, el("th", {text: "stage"}), el("th", {text: "seconds"}), el("th", {text: ""})));
    for (const [name, seconds] of entries) {
      table.append(el("tr", {}, el("td", {text: name}), el("td", {class: "num", text: fmt(seconds, 2)}),
        el("td", {}, el("span", {class: "bar", style: "width:" + Math.round(240 * seconds / longest) + "px"}))));
    }
    document.getElementById("timing-table").append(table);
  })();

  // ---- settings
  (function settings() {
    const body = document.getElementById("settings-body");
    const rows = (object) => {
      const table = el("table", {});
      for (const [k, v] of Object.entries(object)) {
        const text = (v !== null && typeof v === "object") ? JSON.stringify(v) : String(v);
        table.append(el("tr", {}, el("th", {text: k}), el("td", {text: text})));
      }
      return table;
    };
    body.append(el("h3", {text: "Provenance"}), rows(D.provenance));
    if (Object.keys(D.inference).length) body.append(el("h3", {text: "Inference"}), rows(D.inference));
    if (D.config_toml !== null) {
      body.append(el("details", {}, el("summary", {text: "config.toml (every setting of the run)"}),
        el("pre", {text: D.config_toml})));
    }
  })();

  // ---- 3-D view (WebGL 1)
  function decode(text, Type) {
    const binary = atob(text);
    const bytes = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
    return new Type(bytes.buffer);
  }
  const rgb = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16) / 255);
  const M = {
    mul(a, b) { const o = new Float32Array(16);
      for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
        let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s; }
      return o; },
    perspective(fovy, aspect, near, far) { const f = 1 / Math.tan(fovy / 2), o = new Float32Array(16);
      o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1;
      o[14] = 2 * far * near / (near - far); return o; },
    lookAt(eye, at, up) {
      const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
      const norm = (a) => { const l = Math.hypot(...a) || 1; return a.map((x) => x / l); };
      const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
      const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
      const z = norm(sub(eye, at)), x = norm(cross(up, z)), y = cross(z, x);
      return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
        -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]); },
  };

  const canvas = document.getElementById("view");
  const message = document.getElementById("view-message");
  const gl = canvas.getContext("webgl", {antialias: true, preserveDrawingBuffer: true});
  if (!gl) {
    message.hidden = false;
    message.textContent = "This browser offers no WebGL: the 3-D view cannot be drawn.";
    canvas.dataset.status = "no-webgl";
    root.dataset.iprStatus = "no-webgl";
    return;
  }
  const uint32 = gl.getExtension("OES_element_index_uint");
  function program(vertex, fragment) {
    const p = gl.createProgram();
    for (const [type, source] of [[gl.VERTEX_SHADER, vertex], [gl.FRAGMENT_SHADER, fragment]]) {
      const s = gl.createShader(type); gl.shaderSource(s, source); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }
  const shaded = program(
    "attribute vec3 position; attribute vec3 normal; uniform mat4 mvp; varying vec3 n;" +
    "void main(){ n = normal; gl_Position = mvp * vec4(position, 1.0); }",
    "precision mediump float; varying vec3 n; uniform vec4 colour; uniform vec3 light;" +
    "void main(){ float d = abs(dot(normalize(n), light));" +
    " gl_FragColor = vec4(colour.rgb * (0.35 + 0.65 * d), colour.a); }");
  const flat = program(
    "attribute vec3 position; uniform mat4 mvp; uniform float size;" +
    "void main(){ gl_Position = mvp * vec4(position, 1.0); gl_PointSize = size; }",
    "precision mediump float; uniform vec4 colour; void main(){ gl_FragColor = colour; }");
  function buffer(data, target) {
    const b = gl.createBuffer(); gl.bindBuffer(target || gl.ARRAY_BUFFER, b);
    gl.bufferData(target || gl.ARRAY_BUFFER, data, gl.STATIC_DRAW); return b;
  }

  // Scene content: per object its surface (with vertex normals) and its observed points.
  const low = [Infinity, Infinity, Infinity], high = [-Infinity, -Infinity, -Infinity];
  const grow = (v) => { for (let i = 0; i < v.length; i += 3) for (let k = 0; k < 3; k++) {
    low[k] = Math.min(low[k], v[i + k]); high[k] = Math.max(high[k], v[i + k]); } };
  const items = D.objects.map((o) => {
    const v = decode(o.vertices, Float32Array), f32 = decode(o.faces, Uint32Array);
    const normals = new Float32Array(v.length);
    for (let t = 0; t < f32.length; t += 3) {
      const [a, b, c] = [f32[t] * 3, f32[t + 1] * 3, f32[t + 2] * 3];
      const e1 = [v[b] - v[a], v[b + 1] - v[a + 1], v[b + 2] - v[a + 2]];
      const e2 = [v[c] - v[a], v[c + 1] - v[a + 1], v[c + 2] - v[a + 2]];
      const n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
      for (const i of [a, b, c]) for (let k = 0; k < 3; k++) normals[i + k] += n[k];
    }
    const small = v.length / 3 < 65536;
    const faces = small ? Uint16Array.from(f32) : f32;
    if (!small && !uint32) throw new Error("object " + o.id + ": too many vertices for this WebGL");
    grow(v);
    const points = decode(o.points, Float32Array);
    grow(points);
    const centre = [0, 1, 2].map((k) => { let s = 0; for (let i = k; i < v.length; i += 3) s += v[i]; return s / Math.max(1, v.length / 3); });
    return {id: o.id, colour: rgb(o.colour), centre, count: f32.length,
      type: small ? gl.UNSIGNED_SHORT : gl.UNSIGNED_INT,
      vertices: buffer(v), normals: buffer(normals), faces: buffer(faces, gl.ELEMENT_ARRAY_BUFFER),
      points: buffer(points), pointCount: points.length / 3, visible: true};
  });
  const lines = [];
  for (const p of D.pushes) {
    const d = [0, 1, 2].map((k) => p.end[k] - p.start[k]);
    const length = Math.hypot(...d) || 1, u = d.map((x) => x / length);
    const side = [-u[1], u[0], 0], head = Math.min(0.02, 0.3 * length);
    lines.push(...p.start, ...p.end);
    for (const s of [-1, 1]) lines.push(...p.end, ...[0, 1, 2].map((k) => p.end[k] - head * u[k] + s * 0.5 * head * side[k]));
    grow(p.start); grow(p.end);
  }
  if (!isFinite(low[0])) { low.splice(0, 3, -0.1, -0.1, 0); high.splice(0, 3, 0.1, 0.1, 0.1); }
  const centre = [0, 1, 2].map((k) => (low[k] + high[k]) / 2);
  const radius = Math.max(0.05, 0.5 * Math.hypot(high[0] - low[0], high[1] - low[1], high[2] - low[2]));
  // A grid on the plane under the lowest point, 1 cm or 5 cm apart.
  const grid = [], step = radius > 0.3 ? 0.05 : 0.01, reach = Math.ceil(1.4 * radius / step) * step;
  for (let x = -reach; x <= reach + 1e-9; x += step) {
    grid.push(centre[0] + x, centre[1] - reach, low[2], centre[0] + x, centre[1] + reach, low[2]);
    grid.push(centre[0] - reach, centre[1] + x, low[2], centre[0] + reach, centre[1] + x, low[2]);
  }
  const gridBuffer = buffer(new Float32Array(grid)), gridCount = grid.length / 3;
  const lineBuffer = buffer(new Float32Array(lines.length ? lines : [0, 0, 0])), lineCount = lines.length / 3;

  // Orbit camera: from frame 0's camera direction ("camera"), and turned 60 degrees about the
  // vertical from it ("home"), where the parts the camera could not see show.
  const toCamera = [0, 1, 2].map((k) => D.camera[k] - centre[k]);
  const seen = {yaw: Math.atan2(toCamera[1], toCamera[0]),
    pitch: Math.max(-1.4, Math.min(1.4, Math.asin(toCamera[2] / (Math.hypot(...toCamera) || 1)))),
    distance: 2.2 * radius, target: centre.slice()};
  const home = Object.assign({}, seen, {yaw: seen.yaw + Math.PI / 3, pitch: Math.min(seen.pitch, 0.6),
    target: centre.slice()});
  const copy = (v) => Object.assign({}, v, {target: v.target.slice()});
  let view = copy(home);
  const options = {shapes: true, points: true, pushes: true, translucent: true};

  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.957, 0.961, 0.969, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    const c = Math.cos(view.pitch);
    const eye = [view.target[0] + view.distance * c * Math.cos(view.yaw),
      view.target[1] + view.distance * c * Math.sin(view.yaw), view.target[2] + view.distance * Math.sin(view.pitch)];
    const viewMatrix = M.lookAt(eye, view.target, [0, 0, 1]);
    const mvp = M.mul(M.perspective(0.7, w / h, view.distance / 100, view.distance * 10), viewMatrix);
    const light = (() => { const d = [eye[0] - view.target[0], eye[1] - view.target[1], eye[2] - view.target[2] + 0.5 * view.distance];
      const l = Math.hypot(...d); return d.map((x) => x / l); })();
    gl.enable(gl.DEPTH_TEST); gl.depthMask(true); gl.disable(gl.BLEND); gl.disable(gl.CULL_FACE);
    gl.useProgram(flat);
    const fpos = gl.getAttribLocation(flat, "position");
    gl.uniformMatrix4fv(gl.getUniformLocation(flat, "mvp"), false, mvp);
    gl.uniform1f(gl.getUniformLocation(flat, "size"), 2 * dpr);
    const flatColour = gl.getUniformLocation(flat, "colour");
    gl.enableVertexAttribArray(fpos);
    gl.bindBuffer(gl.ARRAY_BUFFER, gridBuffer); gl.vertexAttribPointer(fpos, 3, gl.FLOAT, false, 0, 0);
    gl.uniform4f(flatColour, 0.78, 0.8, 0.83, 1); gl.drawArrays(gl.LINES, 0, gridCount);
    if (options.pushes && lineCount) {
      gl.bindBuffer(gl.ARRAY_BUFFER, lineBuffer); gl.vertexAttribPointer(fpos, 3, gl.FLOAT, false, 0, 0);
      gl.uniform4f(flatColour, 0.05, 0.05, 0.05, 1); gl.drawArrays(gl.LINES, 0, lineCount);
    }
    if (options.points) for (const it of items) {
      if (!it.visible || !it.pointCount) continue;
      gl.bindBuffer(gl.ARRAY_BUFFER, it.points); gl.vertexAttribPointer(fpos, 3, gl.FLOAT, false, 0, 0);
      gl.uniform4f(flatColour, 0.8 * it.colour[0], 0.8 * it.colour[1], 0.8 * it.colour[2], 1);
      gl.drawArrays(gl.POINTS, 0, it.pointCount);
    }
    gl.disableVertexAttribArray(fpos);
    if (options.shapes) {
      gl.useProgram(shaded);
      const pos = gl.getAttribLocation(shaded, "position"), nor = gl.getAttribLocation(shaded, "normal");
      gl.uniformMatrix4fv(gl.getUniformLocation(shaded, "mvp"), false, mvp);
      gl.uniform3fv(gl.getUniformLocation(shaded, "light"), light);
      const colour = gl.getUniformLocation(shaded, "colour");
      gl.enableVertexAttribArray(pos); gl.enableVertexAttribArray(nor);
      const alpha = options.translucent ? 0.38 : 1.0;
      if (options.translucent) {
        gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA); gl.depthMask(false);
      }
      const far = (it) => -Math.hypot(it.centre[0] - eye[0], it.centre[1] - eye[1], it.centre[2] - eye[2]);
      const order = items.filter((it) => it.visible).sort((a, b) => far(a) - far(b));
      gl.enable(gl.CULL_FACE);
      for (const it of order) {
        gl.bindBuffer(gl.ARRAY_BUFFER, it.vertices); gl.vertexAttribPointer(pos, 3, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ARRAY_BUFFER, it.normals); gl.vertexAttribPointer(nor, 3, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, it.faces);
        gl.uniform4f(colour, it.colour[0], it.colour[1], it.colour[2], alpha);
        for (const face of options.translucent ? [gl.FRONT, gl.BACK] : [gl.BACK]) {
          gl.cullFace(face); gl.drawElements(gl.TRIANGLES, it.count, it.type, 0);
        }
      }
      gl.disable(gl.CULL_FACE); gl.disable(gl.BLEND); gl.depthMask(true);
      gl.disableVertexAttribArray(pos); gl.disableVertexAttribArray(nor);
    }
    const error = gl.getError();
    if (error !== gl.NO_ERROR) fail("WebGL error " + error);
  }
  let pending = false;
  const redraw = () => { if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; draw(); }); } };

  // Controls.
  const controls = document.getElementById("controls");
  const toggle = (label, get, set, colour) => {
    const box = el("input", {type: "checkbox"}); box.checked = get();
    box.addEventListener("change", () => { set(box.checked); redraw(); });
    const node = el("label", {}, box); if (colour) node.append(swatch(colour)); node.append(document.createTextNode(label));
    controls.append(node);
  };
  toggle("inferred shapes", () => options.shapes, (v) => { options.shapes = v; });
  toggle("translucent", () => options.translucent, (v) => { options.translucent = v; });
  toggle("observed points", () => options.points, (v) => { options.points = v; });
  toggle("pushes", () => options.pushes, (v) => { options.pushes = v; });
  D.objects.forEach((o, i) => toggle(String(o.id), () => items[i].visible, (v) => { items[i].visible = v; }, o.colour));

  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => { drag = {x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2};
    canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y; drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const s = view.distance / canvas.clientHeight;
      const right = [-Math.sin(view.yaw), Math.cos(view.yaw), 0];
      const up = [-Math.sin(view.pitch) * Math.cos(view.yaw), -Math.sin(view.pitch) * Math.sin(view.yaw), Math.cos(view.pitch)];
      for (let k = 0; k < 3; k++) view.target[k] += s * (-dx * right[k] + dy * up[k]);
    } else {
      view.yaw -= dx * 0.008; view.pitch = Math.max(-1.5, Math.min(1.5, view.pitch + dy * 0.008));
    }
    redraw();
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault();
    view.distance = Math.max(radius * 0.2, Math.min(radius * 30, view.distance * Math.exp(e.deltaY * 0.001))); redraw(); },
    {passive: false});
  canvas.addEventListener("dblclick", () => { view = copy(home); redraw(); });
  for (const [label, start] of [["reset view", home], ["frame 0's camera view", seen]]) {
    const button = el("button", {type: "button", text: label});
    button.addEventListener("click", () => { view = copy(start); redraw(); });
    controls.append(button);
  }
  window.addEventListener("resize", redraw);

  draw();
  const rect = canvas.getBoundingClientRect();
  canvas.dataset.rect = JSON.stringify([rect.left + window.scrollX, rect.top + window.scrollY, rect.width, rect.height]);
  canvas.dataset.status = "drawn";
  canvas.dataset.triangles = String(items.reduce((s, it) => s + it.count / 3, 0));
  canvas.dataset.points = String(items.reduce((s, it) => s + it.pointCount, 0));
  if (!errors.length) root.dataset.iprStatus = "ok";
})();
"""
