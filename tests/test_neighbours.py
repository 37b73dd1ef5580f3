"""Other objects' observed surfaces bound an object's hidden extent (hypotheses.neighbours)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ipr_shapes import voxels
from ipr_shapes.hypotheses import HypothesisConfig, prepare_hypotheses
from ipr_shapes.hypotheses.neighbours import NeighbourSpace, neighbour_spaces
from ipr_shapes.perception.free_space import FREE, OCCUPIED, UNKNOWN, SpaceMap
from ipr_shapes.perception.types import PartialObject

from .box_scene import BOX_HALF, GRID, SUPPORT, partial_box, render_view

BACK = BOX_HALF[1]  # the box's back face, y (m); the camera is on -y
GAP = 0.015  # the neighbour's seen surface is this far behind the box's back (m)


def _patch(object_id: int, y: float) -> PartialObject:
    """A neighbour: a seen vertical surface at ``y`` (m) spanning the box's width and height."""
    x, z = np.meshgrid(np.linspace(-0.06, 0.06, 25), np.linspace(0.002, 0.04, 9))
    points = np.column_stack([x.ravel(), np.full(x.size, y), z.ravel()])
    return PartialObject(
        object_id, 0, np.arange(len(points)), points, np.zeros((len(points), 3), np.uint8)
    )


@pytest.fixture(scope="module")
def scene():
    """The box seen from the front at its own height (its back hidden), and a neighbour's
    surface seen GAP behind it."""
    view = render_view((0.0, -0.5, 0.03))
    box = partial_box(view)
    return (box, _patch(box.id + 1, BACK + GAP)), view.space()


def test_a_neighbours_seen_surface_reads_free_for_the_object_only(scene):
    objects, space = scene
    box, patch = objects
    spaces = neighbour_spaces(objects, space)
    assert set(spaces) == {box.id, patch.id}
    inside_patch = patch.points[:5]
    assert (space.state_at(inside_patch) != FREE).all()  # the map alone does not know
    assert (spaces[box.id].state_at(inside_patch) == FREE).all()
    # The object's own points never read FREE in its own view, whoever else is near.
    assert (spaces[box.id].state_at(box.points) == space.state_at(box.points)).all()
    assert (spaces[patch.id].state_at(inside_patch) == space.state_at(inside_patch)).all()
    # Elsewhere the view is the map.
    probe = np.array([[0.0, 0.2, 0.05], [0.1, -0.1, 0.01], [0.0, 0.1, 0.02]])
    assert (spaces[box.id].state_at(probe) == space.state_at(probe)).all()


def test_the_wrapper_for_other_spaces_agrees_with_the_copied_map(scene):
    objects, space = scene
    box, patch = objects

    class Tracked:  # a seen space that is not a SpaceMap (as fusion's tracked views are not)
        grid = space.grid

        def state_at(self, points):
            return space.state_at(points)

    wrapped = neighbour_spaces(objects, None, {box.id: Tracked()})[box.id]
    copied = neighbour_spaces(objects, space)[box.id]
    assert isinstance(wrapped, NeighbourSpace) and isinstance(copied, SpaceMap)
    rng = np.random.default_rng(0)
    probe = np.concatenate([patch.points, box.points, rng.uniform(-0.1, 0.1, (500, 3))])
    assert (wrapped.state_at(probe) == copied.state_at(probe)).all()
    assert set(np.unique(copied.state)) <= {UNKNOWN, FREE, OCCUPIED}


@pytest.mark.slow
def test_hidden_extent_stops_at_a_neighbours_seen_surface(scene):
    objects, space = scene
    box = objects[0]
    config = HypothesisConfig(count=16, neighbour_surfaces=True)
    alone = prepare_hypotheses(objects, space, (SUPPORT,), dataclasses.replace(
        config, neighbour_surfaces=False), rng=np.random.default_rng(3))  # fmt: skip
    bounded = prepare_hypotheses(objects, space, (SUPPORT,), config, rng=np.random.default_rng(3))

    def reach(prepared) -> float:
        kept = [prepared.generated[box.id][k] for k in prepared.candidates[box.id]]
        return max(float(h.vertices[:, 1].max()) for h in kept)

    # Without the neighbour's surface the hidden side runs through it ...
    assert reach(alone) > BACK + GAP + 0.02
    # ... with it, no kept candidate of the box reaches past it (a voxel and a ray step).
    assert reach(bounded) <= BACK + GAP + 2 * GRID.voxel_size_m
    # and the box still has candidates as deep as the room allows.
    assert reach(bounded) >= BACK
    pitch = voxels.DEFAULT_PITCH_M
    assert all(h.keys(pitch).size for h in bounded.generated[box.id])
