"""Convex physics, then carving (docs/DESIGN_NOTES.md, "Convex physics, then carving"): a bowl's
candidates are convex, so MuJoCo's hull of each is the candidate itself, and its concavity (the
inside the camera saw empty) comes back when the written shape is carved."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull

from ipr_shapes import voxels
from ipr_shapes.carving import SurfaceView, carve_voxels
from ipr_shapes.hypotheses import HypothesisConfig, generate_hypotheses
from ipr_shapes.physics import Body, build_world

from .box_scene import SUPPORT, K, render_view
from .test_hypotheses import assert_valid
from .test_structure import rendered

#: A bowl 14 cm across and 5 cm high with 5 mm walls, standing on the table (z = 0).
PROFILE = [(0.0, 0.0), (0.04, 0.0), (0.07, 0.05), (0.065, 0.05), (0.037, 0.005), (0.0, 0.005)]
INSIDE = np.array([0.0, 0.0, 0.03])  # on the axis, in the bowl's hollow (world, m)


def bowl() -> trimesh.Trimesh:
    return trimesh.creation.revolve(PROFILE + PROFILE[:1], sections=48)


@pytest.fixture(scope="module")
def bowl_seen_from_above():
    obj, space, truth = rendered(bowl(), (0.0, -0.25, 0.35), (0.0, 0.0, 0.02))
    hypotheses = generate_hypotheses(
        obj, space, (SUPPORT,), HypothesisConfig(count=4), np.random.default_rng(0)
    )
    return obj, hypotheses, truth


def test_the_bowl_itself_is_far_from_convex():
    mesh = bowl()
    assert mesh.is_watertight
    assert mesh.volume < 0.3 * ConvexHull(mesh.vertices).volume


def test_a_bowls_candidates_are_convex_and_carving_opens_their_hollow(bowl_seen_from_above):
    """Every candidate (Algorithm 1's and the revolution's) is a closed convex mesh, so the
    physics simulates it exactly; the written shape, carved by what frame 0 saw empty, loses
    the hollow the hull filled while keeping the walls and the bottom."""
    obj, hypotheses, truth = bowl_seen_from_above
    assert "revolution" in {h.generator for h in hypotheses}
    view = render_view(
        (0.0, -0.25, 0.35), target=(0.0, 0.0, 0.02), box=(bowl().vertices, bowl().faces)
    )
    surface = SurfaceView(np.where(view.depth > 0, view.depth, 0.0), K, view.world_from_camera, 0.0)
    inside_key = voxels.pack(np.floor(INSIDE / voxels.DEFAULT_PITCH_M).astype(np.int64)[None])
    for h in hypotheses:
        assert_valid(h, obj.points, convex_tolerance=1e-8)
        keys = h.keys(voxels.DEFAULT_PITCH_M)
        assert np.isin(inside_key, keys).all()  # the hull fills the hollow
        carved = carve_voxels(keys, obj.id, [surface])
        assert not np.isin(inside_key, carved).any()  # carving empties it
        # The walls and the bottom the camera saw stay.
        assert voxels.intersection_count(carved, truth) >= 0.8 * voxels.intersection_count(
            keys, truth
        )


def test_the_physics_collides_a_bowl_as_its_hull():
    """What the physics is given is collided as its convex hull: a ball dropped into a
    non-convex bowl mesh rests on the hull's top, which is why candidates must be convex (or
    be given as convex pieces) for their physics to be their shape."""
    mesh = bowl()
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.015)
    ball.apply_translation([0.0, 0.0, 0.08])
    world = build_world(
        [Body(np.asarray(mesh.vertices), np.asarray(mesh.faces), dynamic=False),
         Body(np.asarray(ball.vertices), np.asarray(ball.faces))],
        (SUPPORT,),
    )  # fmt: skip
    world.settle(2.0)
    centre = world.poses()[1] @ np.array([0.0, 0.0, 0.08, 1.0])
    assert centre[2] == pytest.approx(0.05 + 0.015, abs=0.003)
