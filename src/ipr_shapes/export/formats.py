"""Files of each export format, written into a folder (``ipr_shapes.export.export_result`` stages it).

Every format writes ``export.json`` (the manifest: units, frames, support, density and per
object its pose, mass, inertia, volumes and files). Besides it:

- ``mjcf``: ``scene.xml`` (``ipr_shapes.export.mjcf``) and ``meshes/``.
- ``urdf``: ``object_<id>.urdf`` per object (one link: inertial, visual surface, collision
  pieces; URDF has no world pose, see the manifest) and ``meshes/``. Each carries MuJoCo's
  ``<mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>`` extension, which
  other readers ignore, so that MuJoCo keeps the visual mesh and the link. With walls,
  ``walls.urdf``: one massless link holding every wall's slab in world coordinates (load it
  with a fixed base).
- ``sdf``: ``scene.sdf`` (SDF 1.7 world: a static support plane model, a static ``walls``
  model when the result has walls, and one model per object at its pose) and
  ``object_<id>.sdf`` (the model alone, at the origin), ``meshes/``.
- ``obj``: ``meshes/`` only (surfaces and collision pieces, object frames; walls, world).
- ``glb``: ``scene.glb``, one node per object (its surface, coloured) at its pose and one per
  wall; the scene's root node turns the z-up world into glTF's y-up (glTF x, y, z = world x,
  z, -y).

Meshes are Wavefront OBJ in metres, in each object's frame: ``meshes/object_<id>.obj`` (the
smooth surface, with vertex normals) and ``meshes/object_<id>_collision_<n>.obj`` (convex);
each wall's convex slab in the world frame: ``meshes/wall_<k>.obj``.
Mesh paths in URDF and SDF are relative to the file that names them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ipr_shapes.export.mjcf import (
    MESH_DIR,
    collision_files,
    colour,
    mesh_files,
    mjcf_document,
    number,
    numbers,
    obj_bytes,
    surface_file,
    wall_file,
    wall_mesh,
)
from ipr_shapes.export.model import ExportConfig, ObjectBody
from ipr_shapes.export.placement import SceneBodies

EXPORT_FORMAT = "ipr-export/1"
MANIFEST = "export.json"
#: The y-up glTF frame from the z-up world: glTF (x, y, z) = world (x, z, -y).
GLTF_FROM_WORLD = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def rpy(rotation: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (rad) of a rotation matrix, URDF/SDF's fixed-axis x-y-z convention
    (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    import warnings

    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():  # gimbal lock: a valid triple, with yaw 0, all the same
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(rotation).as_euler("xyz")


def write_meshes(folder: Path, scene: SceneBodies) -> None:
    (folder / MESH_DIR).mkdir(parents=True, exist_ok=True)
    for name, content in mesh_files(scene.objects).items():
        (folder / MESH_DIR / name).write_bytes(content)
    for k, wall in enumerate(scene.walls):
        (folder / MESH_DIR / wall_file(k)).write_bytes(obj_bytes(wall_mesh(wall), normals=False))


def write_mjcf(folder: Path, scene: SceneBodies, config: ExportConfig) -> list[str]:
    write_meshes(folder, scene)
    text, _ = mjcf_document(scene.objects, scene.support_z_m, config, walls=scene.walls)
    (folder / "scene.xml").write_text(text, encoding="utf-8")
    return ["scene.xml"]


def _inertia_elements(parent: ET.Element, body: ObjectBody, sdf: bool) -> None:
    """Inertial of ``body`` in the principal frame (diagonal tensor, rotated)."""
    inertial = ET.SubElement(parent, "inertial")
    moments = body.principal_moments_kg_m2
    angles = rpy(body.principal_axes)
    if sdf:
        ET.SubElement(inertial, "pose").text = numbers([0.0, 0.0, 0.0, *angles])
        ET.SubElement(inertial, "mass").text = number(body.mass_kg)
        tensor = ET.SubElement(inertial, "inertia")
        for key, value in zip(
            ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
            (moments[0], 0.0, 0.0, moments[1], 0.0, moments[2]),
            strict=True,
        ):
            ET.SubElement(tensor, key).text = number(value)
    else:
        ET.SubElement(inertial, "origin", xyz="0 0 0", rpy=numbers(angles))
        ET.SubElement(inertial, "mass", value=number(body.mass_kg))
        ET.SubElement(
            inertial,
            "inertia",
            ixx=number(moments[0]),
            ixy="0",
            ixz="0",
            iyy=number(moments[1]),
            iyz="0",
            izz=number(moments[2]),
        )


def urdf_document(body: ObjectBody) -> str:
    """The URDF text of one object: a single link named like it (module doc)."""
    robot = ET.Element("robot", name=body.name)
    mujoco = ET.SubElement(robot, "mujoco")
    ET.SubElement(mujoco, "compiler", discardvisual="false", fusestatic="false")
    material = ET.SubElement(robot, "material", name=f"{body.name}_colour")
    ET.SubElement(material, "color", rgba=numbers(colour(body.id)))
    link = ET.SubElement(robot, "link", name=body.name)
    _inertia_elements(link, body, sdf=False)
    visual = ET.SubElement(link, "visual")
    ET.SubElement(visual, "origin", xyz="0 0 0", rpy="0 0 0")
    geometry = ET.SubElement(visual, "geometry")
    ET.SubElement(geometry, "mesh", filename=f"{MESH_DIR}/{surface_file(body)}")
    ET.SubElement(visual, "material", name=f"{body.name}_colour")
    for name in collision_files(body):
        collision = ET.SubElement(link, "collision")
        ET.SubElement(collision, "origin", xyz="0 0 0", rpy="0 0 0")
        geometry = ET.SubElement(collision, "geometry")
        ET.SubElement(geometry, "mesh", filename=f"{MESH_DIR}/{name}")
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def walls_urdf_document(count: int) -> str:
    """The URDF text of the walls: one link without inertia (static when loaded with a fixed
    base) holding each wall's slab (``meshes/wall_<k>.obj``, world coordinates)."""
    robot = ET.Element("robot", name="walls")
    mujoco = ET.SubElement(robot, "mujoco")
    ET.SubElement(mujoco, "compiler", discardvisual="false", fusestatic="false")
    link = ET.SubElement(robot, "link", name="walls")
    for k in range(count):
        for kind in ("visual", "collision"):
            element = ET.SubElement(link, kind)
            ET.SubElement(element, "origin", xyz="0 0 0", rpy="0 0 0")
            geometry = ET.SubElement(element, "geometry")
            ET.SubElement(geometry, "mesh", filename=f"{MESH_DIR}/{wall_file(k)}")
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def write_urdf(folder: Path, scene: SceneBodies, config: ExportConfig) -> list[str]:
    write_meshes(folder, scene)
    names = []
    for body in scene.objects:
        names.append(f"{body.name}.urdf")
        (folder / names[-1]).write_text(urdf_document(body), encoding="utf-8")
    if scene.walls:
        names.append("walls.urdf")
        (folder / names[-1]).write_text(walls_urdf_document(len(scene.walls)), encoding="utf-8")
    return names


def _sdf_friction(parent: ET.Element, config: ExportConfig) -> None:
    surface = ET.SubElement(parent, "surface")
    ode = ET.SubElement(ET.SubElement(surface, "friction"), "ode")
    ET.SubElement(ode, "mu").text = number(config.friction[0])
    ET.SubElement(ode, "mu2").text = number(config.friction[0])


def _sdf_model(body: ObjectBody, config: ExportConfig, pose: bool) -> ET.Element:
    model = ET.Element("model", name=body.name)
    if pose:
        ET.SubElement(model, "pose").text = numbers([*body.position_m, 0.0, 0.0, 0.0])
    link = ET.SubElement(model, "link", name=body.name)
    _inertia_elements(link, body, sdf=True)
    visual = ET.SubElement(link, "visual", name="visual")
    mesh = ET.SubElement(ET.SubElement(visual, "geometry"), "mesh")
    ET.SubElement(mesh, "uri").text = f"{MESH_DIR}/{surface_file(body)}"
    material = ET.SubElement(visual, "material")
    ET.SubElement(material, "ambient").text = numbers(colour(body.id))
    ET.SubElement(material, "diffuse").text = numbers(colour(body.id))
    for n, name in enumerate(collision_files(body)):
        collision = ET.SubElement(link, "collision", name=f"collision_{n}")
        mesh = ET.SubElement(ET.SubElement(collision, "geometry"), "mesh")
        ET.SubElement(mesh, "uri").text = f"{MESH_DIR}/{name}"
        _sdf_friction(collision, config)
    return model


def sdf_world(scene: SceneBodies, config: ExportConfig) -> str:
    """The SDF 1.7 world of the scene (module doc)."""
    root = ET.Element("sdf", version="1.7")
    world = ET.SubElement(root, "world", name="ipr_scene")
    ET.SubElement(world, "gravity").text = "0 0 -9.81"
    light = ET.SubElement(world, "light", type="directional", name="sun")
    ET.SubElement(light, "pose").text = "0 0 3 0 0 0"
    ET.SubElement(light, "direction").text = "0 0 -1"
    support = ET.SubElement(world, "model", name="support")
    ET.SubElement(support, "static").text = "true"
    ET.SubElement(support, "pose").text = numbers([0.0, 0.0, scene.support_z_m, 0.0, 0.0, 0.0])
    link = ET.SubElement(support, "link", name="support")
    for kind in ("collision", "visual"):
        element = ET.SubElement(link, kind, name=kind)
        plane = ET.SubElement(ET.SubElement(element, "geometry"), "plane")
        ET.SubElement(plane, "normal").text = "0 0 1"
        ET.SubElement(plane, "size").text = "2 2"
        if kind == "collision":
            _sdf_friction(element, config)
    if scene.walls:
        walls = ET.SubElement(world, "model", name="walls")
        ET.SubElement(walls, "static").text = "true"
        link = ET.SubElement(walls, "link", name="walls")
        for k in range(len(scene.walls)):
            for kind in ("collision", "visual"):
                element = ET.SubElement(link, kind, name=f"wall_{k}_{kind}")
                mesh = ET.SubElement(ET.SubElement(element, "geometry"), "mesh")
                ET.SubElement(mesh, "uri").text = f"{MESH_DIR}/{wall_file(k)}"
                if kind == "collision":
                    _sdf_friction(element, config)
    for body in scene.objects:
        world.append(_sdf_model(body, config, pose=True))
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def sdf_model(body: ObjectBody, config: ExportConfig) -> str:
    """The SDF 1.7 model of one object, its frame at the model's origin."""
    root = ET.Element("sdf", version="1.7")
    root.append(_sdf_model(body, config, pose=False))
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_sdf(folder: Path, scene: SceneBodies, config: ExportConfig) -> list[str]:
    write_meshes(folder, scene)
    (folder / "scene.sdf").write_text(sdf_world(scene, config), encoding="utf-8")
    names = ["scene.sdf"]
    for body in scene.objects:
        names.append(f"{body.name}.sdf")
        (folder / names[-1]).write_text(sdf_model(body, config), encoding="utf-8")
    return names


def write_obj(folder: Path, scene: SceneBodies, config: ExportConfig) -> list[str]:
    write_meshes(folder, scene)
    return []


def glb_scene(scene: SceneBodies) -> Any:
    """A trimesh Scene: one coloured node per object surface at its pose, y-up (module doc)."""
    import trimesh

    result = trimesh.Scene()
    for body in scene.objects:
        mesh = body.surface.copy()
        rgba = np.round(np.array(colour(body.id)) * 255).astype(np.uint8)
        mesh.visual = trimesh.visual.ColorVisuals(
            mesh, face_colors=np.tile(rgba, (len(mesh.faces), 1))
        )
        result.add_geometry(
            mesh,
            node_name=body.name,
            geom_name=body.name,
            transform=GLTF_FROM_WORLD @ body.world_from_object,
        )
    for k, wall in enumerate(scene.walls):
        mesh = wall_mesh(wall)
        mesh.visual = trimesh.visual.ColorVisuals(
            mesh, face_colors=np.tile([178, 178, 173, 128], (len(mesh.faces), 1)).astype(np.uint8)
        )
        result.add_geometry(
            mesh, node_name=f"wall_{k}", geom_name=f"wall_{k}", transform=GLTF_FROM_WORLD
        )
    return result


def write_glb(folder: Path, scene: SceneBodies, config: ExportConfig) -> list[str]:
    (folder / "scene.glb").write_bytes(glb_scene(scene).export(file_type="glb"))
    return ["scene.glb"]


#: Format name -> writer(folder, scene, config) returning the model files it wrote.
WRITERS: dict[str, Callable[[Path, SceneBodies, ExportConfig], list[str]]] = {
    "mjcf": write_mjcf,
    "urdf": write_urdf,
    "sdf": write_sdf,
    "obj": write_obj,
    "glb": write_glb,
}
#: The export formats.
FORMATS = tuple(WRITERS)


def manifest(
    scene: SceneBodies,
    config: ExportConfig,
    export_format: str,
    files: list[str],
    source: dict[str, Any],
    timing_s: dict[str, float],
) -> dict[str, Any]:
    """The content of ``export.json``."""
    from scipy.spatial.transform import Rotation

    meshes = export_format != "glb"
    objects = []
    for body in scene.objects:
        objects.append(
            {
                "id": body.id,
                "name": body.name,
                "probability": body.probability,
                "position_m": body.position_m.tolist(),
                "quaternion_xyzw": [0.0, 0.0, 0.0, 1.0],
                "world_from_object": body.world_from_object.tolist(),
                "displacement_m": body.displacement_m.tolist(),
                "rotation_deg": body.rotation_deg,
                "mass_kg": body.mass_kg,
                "inertia_kg_m2": body.inertia_kg_m2.tolist(),
                "principal_moments_kg_m2": body.principal_moments_kg_m2.tolist(),
                "principal_axes_xyzw": Rotation.from_matrix(body.principal_axes).as_quat().tolist(),
                "volume_m3": body.volume_m3,
                "voxel_volume_m3": body.voxel_volume_m3,
                "volume_error": body.volume_error,
                "collision_volume_m3": float(sum(piece.volume for piece in body.collision)),
                "surface_source": body.surface_source,
                "surface": f"{MESH_DIR}/{surface_file(body)}" if meshes else None,
                "collision": [f"{MESH_DIR}/{name}" for name in collision_files(body)]
                if meshes
                else [],
                "surface_faces": len(body.surface.faces),
                "timing_s": body.timing_s,
            }
        )
    return {
        "format": EXPORT_FORMAT,
        "export_format": export_format,
        "files": files,
        "source": source,
        "units": {"length": "m", "mass": "kg", "inertia": "kg m^2", "angle": "rad"},
        "frames": "world: the result's (z up, gravity -z); object: origin at the centre of "
        "mass, axes parallel to the world's; position_m and world_from_object place it",
        "density_kg_m3": config.density_kg_m3,
        "collision_method": config.collision,
        "support": {
            "type": "plane",
            "normal": [0.0, 0.0, 1.0],
            "height_m": scene.support_z_m,
            "source": scene.support_source,
        },
        "walls": [
            {
                "name": f"wall_{k}",
                "vertices_m": np.asarray(wall).tolist(),
                "mesh": f"{MESH_DIR}/{wall_file(k)}" if meshes else None,
            }
            for k, wall in enumerate(scene.walls)
        ],
        "max_penetration_m": scene.max_penetration_m,
        "settling": {
            "enabled": config.settle,
            "simulated_s": scene.settle_s,
            "at_rest": scene.at_rest,
            "max_displacement_m": max(
                (float(np.linalg.norm(body.displacement_m)) for body in scene.objects), default=0.0
            ),
            "max_rotation_deg": max((body.rotation_deg for body in scene.objects), default=0.0),
        },
        "objects": objects,
        "timing_s": timing_s,
    }
