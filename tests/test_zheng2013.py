"""The Zheng et al. 2013 baseline: Manhattan boxes grown into unseen space, stability grouping."""

from __future__ import annotations

import numpy as np
import pytest

from ipr_shapes import voxels
from ipr_shapes.baselines import ZhengConfig, zheng2013
from ipr_shapes.baselines.zheng2013 import manhattan_frame
from ipr_shapes.perception.free_space import FREE
from ipr_shapes.perception.types import Facet, PartialObject
from ipr_shapes.result import load_result, write_posterior_result

from .box_scene import SUPPORT, box_mesh, partial_box, render_view

#: The view from above and in front sees the box's top and front; its back half is hidden.
OBLIQUE_EYE = (0.0, -0.3, 0.3)
#: The box is completed to at least this voxel IoU with the true box (measured 0.92: its back
#: face a slab from the true one, where seen free space begins); the hull of the observed
#: points has 0.46.
MIN_IOU = 0.85


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return voxels.intersection_count(a, b) / voxels.count(voxels.union(a, b))


@pytest.fixture(scope="module")
def oblique():
    view = render_view(OBLIQUE_EYE)
    return view, partial_box(view, object_id=1), view.space()


def test_a_partly_seen_box_is_completed_to_its_true_extent(oblique):
    view, box, space = oblique
    outcome = zheng2013((box,), space, (SUPPORT,), camera_m=view.world_from_camera[:3, 3])
    (posterior,) = outcome.posteriors
    shape = posterior.hypotheses[0]
    assert posterior.probabilities.tolist() == [1.0] and posterior.best == 0
    truth = voxels.scanline_voxels(*box_mesh(), voxels.DEFAULT_PITCH_M)
    assert _iou(shape.keys(), truth) > MIN_IOU
    # The observed points alone span much less: the growth into the unseen space did it.
    seen = voxels.scanline_voxels(*_hull(box.points), voxels.DEFAULT_PITCH_M)
    assert _iou(seen, truth) < 0.5
    # Closed, contains every observed point, stands on the support (z = 0).
    assert voxels.is_closed(shape.vertices, shape.faces)
    assert shape.contains(box.points, tolerance_m=1e-4).all()
    assert shape.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    assert outcome.unstable == () and outcome.groups == []


def _hull(points):
    from ipr_shapes.geometry.convex import convex_mesh

    vertices, faces, _ = convex_mesh(points)
    return vertices, faces


def test_the_written_solid_leaves_the_seen_free_space_empty():
    view = render_view((0.3, -0.4, 0.3))  # from a corner: two sides and the top seen
    box, space = partial_box(view, object_id=1), view.space()
    # Without the camera every horizontal face may grow: only free space stops the front ones.
    (posterior,) = zheng2013((box,), space, (SUPPORT,)).posteriors
    vertices, faces = posterior.output_mesh
    assert voxels.is_closed(vertices, faces)
    solid = voxels.scanline_voxels(vertices, faces, voxels.DEFAULT_PITCH_M)
    centres = voxels.centres(solid, voxels.DEFAULT_PITCH_M)
    assert np.mean(space.state_at(centres) == FREE) == 0.0
    # Its box did reach into seen-free space (a slab is allowed 10 %): the solid removed it.
    box_centres = voxels.centres(posterior.hypotheses[0].keys(), voxels.DEFAULT_PITCH_M)
    assert np.any(space.state_at(box_centres) == FREE)


def test_free_space_stops_the_growth():
    """With the space a camera saw empty behind the box, the box is not grown into it; with no
    free-space map it grows to its cap (its longest visible side)."""
    view = render_view((0.0, -0.5, 0.03))  # from the box's height: its depth is hidden
    box = partial_box(view, object_id=1)
    camera = view.world_from_camera[:3, 3]
    grown = zheng2013((box,), None, (SUPPORT,), camera_m=camera).posteriors[0].hypotheses[0]
    assert grown.bounds[1, 1] - grown.bounds[0, 1] == pytest.approx(0.1, abs=0.006)
    space = view.space()
    state = space.state.copy()
    behind = space.grid.centres()[..., 1] > 0.045  # the camera saw past y = 4.5 cm
    state[behind] = FREE
    seen = type(space)(space.grid, state)
    stopped = zheng2013((box,), seen, (SUPPORT,), camera_m=camera).posteriors[0].hypotheses[0]
    assert stopped.bounds[1, 1] <= 0.045 + 1e-6
    assert stopped.bounds[1, 1] > 0.02  # it still grew behind the seen face (y = -0.03)


def _surface_object(object_id: int, low, high, step=0.005) -> PartialObject:
    """Points on a box's top and four sides (not its bottom), one facet per side."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    facets, points = [], []
    for axis in range(3):
        for side, value in ((-1, low[axis]), (1, high[axis])):
            if axis == 2 and side < 0:
                continue
            others = [k for k in range(3) if k != axis]
            a = np.arange(low[others[0]], high[others[0]] + 1e-9, step)
            b = np.arange(low[others[1]], high[others[1]] + 1e-9, step)
            grid = np.stack(np.meshgrid(a, b, indexing="ij"), -1).reshape(-1, 2)
            face = np.empty((len(grid), 3))
            face[:, axis] = value
            face[:, others] = grid
            normal = np.zeros(3)
            normal[axis] = side
            area = float(np.prod(high[others] - low[others]))
            facets.append(Facet(face.mean(axis=0), normal, face, area))
            points.append(face)
    points = np.concatenate(points)
    return PartialObject(
        object_id, 0, np.arange(len(points)), points, np.zeros((len(points), 3), np.uint8),
        tuple(facets),
    )  # fmt: skip


def test_an_overhanging_object_stands_only_grouped_with_what_supports_it():
    """A plank on a block, its centre of mass past the block's edge: alone it topples; welded
    to the block it stands (the original's grouping of unstable primitives)."""
    block = _surface_object(2, (-0.05, -0.05, 0.0), (0.05, 0.05, 0.10))
    plank = _surface_object(1, (0.0, -0.02, 0.10), (0.12, 0.02, 0.11))
    outcome = zheng2013((plank, block), None, (SUPPORT,))
    shapes = {p.object_id: p.hypotheses[0] for p in outcome.posteriors}
    # The plank stops on the block instead of filling down to the support.
    assert shapes[1].bounds[0, 2] == pytest.approx(0.10, abs=0.006)
    assert shapes[2].bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    assert outcome.groups == [(1, 2)]
    assert outcome.unstable == ()
    # Alone, the plank does fall: the grouping was needed.
    from ipr_shapes.baselines.zheng2013 import _unstable

    alone = _unstable([shapes[1], shapes[2]], (SUPPORT,), ZhengConfig())
    assert alone.tolist() == [True, False]


def test_the_manhattan_frame_follows_the_objects_faces():
    angle = np.deg2rad(30.0)
    rotation = np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    block = _surface_object(1, (-0.05, -0.03, 0.0), (0.05, 0.03, 0.04))
    turned = PartialObject(
        1, 0, block.pixels, block.points @ rotation.T, block.colours,
        tuple(
            Facet(f.centre @ rotation.T, rotation @ f.normal, f.points @ rotation.T, f.area_m2)
            for f in block.facets
        ),
    )  # fmt: skip
    frame = manhattan_frame((turned,), np.array([0.0, 0.0, 1.0]))
    # e1 is the rotated x or y axis (modulo 90 degrees).
    assert max(abs(frame[:, 0] @ rotation[:, 0]), abs(frame[:, 0] @ rotation[:, 1])) > 0.9999
    (posterior,) = zheng2013((turned,), None, (SUPPORT,)).posteriors
    # The box's faces are the block's: its corners take two values along each turned axis, and
    # it spans the block's 10 cm and 4 cm (with no free-space map, the 6 cm side grows to 10).
    local = posterior.hypotheses[0].vertices @ rotation
    spans = np.sort(local.max(axis=0) - local.min(axis=0))
    assert spans == pytest.approx([0.04, 0.1, 0.1], abs=1e-6)


def test_the_result_is_a_normal_result(tmp_path, oblique):
    view, box, space = oblique
    outcome = zheng2013((box,), space, (SUPPORT,))
    out = write_posterior_result(
        tmp_path / "result", outcome.posteriors, {0: view.world_from_camera}, {"total": 0.1},
        method="zheng2013",
    )  # fmt: skip
    result = load_result(out)
    assert result.method == "zheng2013"
    (obj,) = result.objects
    assert obj.probability == 1.0
    assert obj.mesh.is_watertight


def test_bad_settings_are_refused():
    from ipr_shapes.errors import IprError

    with pytest.raises((IprError, ValueError)):
        ZhengConfig(frame="sideways")
    with pytest.raises((IprError, ValueError)):
        ZhengConfig(max_free_fraction=1.5)


@pytest.mark.slow
def test_ipr_infer_zheng2013_end_to_end_then_eval(tmp_path):
    """``ipr-shapes infer --method zheng2013`` on a synthetic pile writes a result ``ipr-shapes eval`` scores."""
    import json

    from ipr_shapes.cli import main
    from ipr_shapes.synth import SynthConfig, generate_scene

    scene = generate_scene(
        tmp_path / "scenes", kind="static", seed=2, arrangement="table",
        config=SynthConfig(width=320, height=240),
    )  # fmt: skip
    out = tmp_path / "result"
    assert main(["infer", str(scene), "-o", str(out), "--method", "zheng2013"]) == 0
    result = load_result(out)
    assert result.method == "zheng2013" and len(result.objects) >= 2
    for obj in result.objects:
        assert obj.probability == 1.0
        assert obj.load_mesh().is_watertight
    metrics_file = tmp_path / "metrics.json"
    assert main(["eval", str(scene), str(out), "--json", str(metrics_file)]) == 0
    metrics = json.loads(metrics_file.read_text())
    assert 0.2 < metrics["object_space"]["iou"] < 0.99
