"""The MJCF document of an exported scene (MuJoCo's own format), and the mesh files every format
shares.

One model: the support as a plane geom at z = ``support_z_m``; each wall the result records a
static geom (``wall_<k>``: a mesh whose vertices are written inline, its slab's convex hull);
each object a body at its pose
with a free joint, an explicit ``<inertial>`` (mass, principal moments, principal axes as the
inertial frame's quaternion), its smooth surface as a visual geom (group 2, no contacts, no
mass) and its convex pieces as collision geoms (group 3, hidden by default, friction as the
inference's). Options as ``ipr_shapes.physics``: implicit-fast integrator, elliptic cones,
``impratio`` 10, gravity -9.81 along z.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import Any

import numpy as np

from ipr_shapes.export.model import ExportConfig, ObjectBody
from ipr_shapes.perception.output import palette

#: Folder of the mesh files, relative to the exported model files.
MESH_DIR = "meshes"


def number(value: float) -> str:
    """A float as short exact-enough text (9 significant digits, no "-0")."""
    text = f"{float(value):.9g}"
    return "0" if text == "-0" else text


def numbers(values: Any) -> str:
    return " ".join(number(v) for v in np.asarray(values, dtype=np.float64).ravel())


def colour(object_id: int) -> tuple[float, float, float, float]:
    """RGBA in [0, 1] of an object: its id's colour in the overlays, completion.png and
    report.html (``ipr_shapes.perception.output.palette``)."""
    red, green, blue = (float(c) / 255.0 for c in palette(np.array([object_id]))[0])
    return (red, green, blue, 1.0)


def surface_file(body: ObjectBody) -> str:
    """File name of an object's surface mesh (object frame, OBJ)."""
    return f"{body.name}.obj"


def collision_files(body: ObjectBody) -> list[str]:
    """File names of an object's convex collision pieces (object frame, OBJ)."""
    return [f"{body.name}_collision_{n}.obj" for n in range(len(body.collision))]


def obj_bytes(mesh: Any, normals: bool) -> bytes:
    """Wavefront OBJ text of a trimesh (vertices, faces and, with ``normals``, vertex normals)."""
    from trimesh.exchange.obj import export_obj

    return export_obj(mesh, include_normals=normals, include_texture=False, header=None).encode()


def wall_file(k: int) -> str:
    """The OBJ file name of wall ``k``'s slab (under ``MESH_DIR`` beside URDF and SDF files)."""
    return f"wall_{k}.obj"


def wall_mesh(vertices: np.ndarray) -> Any:
    """The closed convex mesh (trimesh, m, world) of a wall slab's (V, 3) vertices."""
    import trimesh

    return trimesh.convex.convex_hull(np.asarray(vertices, dtype=np.float64))


def mesh_files(objects: Sequence[ObjectBody], collision_only: bool = False) -> dict[str, bytes]:
    """File name -> OBJ bytes of every object's surface (unless ``collision_only``) and pieces."""
    files = {}
    for body in objects:
        if not collision_only:
            files[surface_file(body)] = obj_bytes(body.surface, normals=True)
        for name, piece in zip(collision_files(body), body.collision, strict=True):
            files[name] = obj_bytes(piece, normals=False)
    return files


def principal_quaternion(body: ObjectBody) -> np.ndarray:
    """(w, x, y, z) of the rotation from the object frame to its principal axes."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(body.principal_axes).as_quat(scalar_first=True)


def mjcf_document(
    objects: Sequence[ObjectBody],
    support_z_m: float,
    config: ExportConfig,
    *,
    collision_only: bool = False,
    embed: bool = False,
    model_name: str = "ipr_export",
    walls: Sequence[np.ndarray] = (),
) -> tuple[str, dict[str, bytes]]:
    """The MJCF text of the scene (module doc) and its mesh files (name -> bytes). ``walls``:
    per wall the (V, 3) vertices (m, world) of a static convex slab, written inline as a mesh
    (MuJoCo takes the convex hull of a mesh's vertices for collisions).

    With ``embed`` the meshes are named without a folder, for
    ``mujoco.MjModel.from_xml_string(text, files)``; otherwise they are read from ``meshes/``
    beside the MJCF file. ``collision_only`` leaves the visual surfaces out.
    """
    root = ET.Element("mujoco", model=model_name)
    compiler = ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    if not embed:
        compiler.set("meshdir", MESH_DIR)
    ET.SubElement(
        root,
        "option",
        timestep=number(config.timestep_s),
        gravity="0 0 -9.81",
        integrator="implicitfast",
        cone="elliptic",
        impratio="10",
    )
    default = ET.SubElement(root, "default")
    visual = ET.SubElement(default, "default", {"class": "visual"})
    ET.SubElement(visual, "geom", type="mesh", contype="0", conaffinity="0", group="2", mass="0")
    collision = ET.SubElement(default, "default", {"class": "collision"})
    ET.SubElement(
        collision, "geom", type="mesh", group="3", condim="6", friction=numbers(config.friction)
    )
    assets = ET.SubElement(root, "asset")
    for body in objects:
        if not collision_only:
            ET.SubElement(assets, "mesh", name=body.name, file=surface_file(body))
        for n, name in enumerate(collision_files(body)):
            ET.SubElement(assets, "mesh", name=f"{body.name}_collision_{n}", file=name)
    for k, wall in enumerate(walls):
        ET.SubElement(assets, "mesh", name=f"wall_{k}", vertex=numbers(np.ravel(wall)))
    world = ET.SubElement(root, "worldbody")
    ET.SubElement(
        world,
        "light",
        name="sun",
        pos="0 0 3",
        dir="0 0 -1",
        directional="true",
        castshadow="false",
    )
    extent = _support_half_extent(objects)
    ET.SubElement(
        world,
        "geom",
        name="support",
        type="plane",
        pos=numbers([0.0, 0.0, support_z_m]),
        size=numbers([extent, extent, 0.05]),
        condim="6",
        friction=numbers(config.friction),
        rgba="0.8 0.8 0.78 1",
    )
    for k in range(len(walls)):
        ET.SubElement(
            world,
            "geom",
            name=f"wall_{k}",
            type="mesh",
            mesh=f"wall_{k}",
            condim="6",
            friction=numbers(config.friction),
            rgba="0.7 0.7 0.68 0.5",
        )
    for body in objects:
        element = ET.SubElement(world, "body", name=body.name, pos=numbers(body.position_m))
        ET.SubElement(element, "freejoint", name=body.name)
        ET.SubElement(
            element,
            "inertial",
            pos="0 0 0",
            quat=numbers(principal_quaternion(body)),
            mass=number(body.mass_kg),
            diaginertia=numbers(body.principal_moments_kg_m2),
        )
        if not collision_only:
            ET.SubElement(
                element,
                "geom",
                {"class": "visual"},
                name=f"{body.name}_visual",
                mesh=body.name,
                rgba=numbers(colour(body.id)),
            )
        for n in range(len(body.collision)):
            ET.SubElement(
                element,
                "geom",
                {"class": "collision"},
                name=f"{body.name}_collision_{n}",
                mesh=f"{body.name}_collision_{n}",
            )
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n", mesh_files(objects, collision_only)


def _support_half_extent(objects: Sequence[ObjectBody]) -> float:
    """Half side of the drawn support plane (m): the objects' reach from the origin plus 0.3 m."""
    reach = max((float(np.abs(body.position_m[:2]).max()) for body in objects), default=0.0)
    return reach + 0.3
