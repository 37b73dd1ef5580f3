"""The exported scene's support plane and the objects' start poses, separated so that nothing
starts interpenetrating.

- **Support**: the plane z = 0 of the world frame (the contract's support, or the plane the
  world frame was built from), unless the lowest object point lies more than
  ``ExportConfig.support_search_m`` from it (a world from camera poses with the table
  elsewhere): then the plane through the lowest object point. ``ExportConfig.support_z_m``
  sets it. Results carry no walls, so none is exported.
- **Separation**: MuJoCo computes the contacts of the collision pieces at the start poses; an
  object that penetrates the support is lifted by its depth, and of two objects that
  penetrate each other the one whose centre of mass is higher moves out along the contact
  normal by the depth, repeated until no contact is deeper than
  ``ExportConfig.separation_tolerance_m``. Each object's displacement is recorded
  (``ObjectBody.displacement_m``): the size of the voxels' and the smoothing's rounding, about
  a millimetre.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ipr_shapes.export.mjcf import mjcf_document
from ipr_shapes.export.model import ExportConfig, ObjectBody


@dataclass(frozen=True, eq=False)
class SceneBodies:
    """The exported scene: the support plane z = ``support_z_m`` (normal +z) and the objects.

    ``support_source`` says how the height was chosen; ``max_penetration_m`` is the deepest
    contact left after separation (0 when every start pose is clear).
    """

    support_z_m: float
    support_source: str
    objects: tuple[ObjectBody, ...]
    max_penetration_m: float


def scene_bodies(objects: Sequence[ObjectBody], config: ExportConfig | None = None) -> SceneBodies:
    """The support plane and the objects with separated start poses (module doc)."""
    config = config or ExportConfig()
    lowest = min(
        (float(body.surface.vertices[:, 2].min() + body.position_m[2]) for body in objects),
        default=0.0,
    )
    if config.support_z_m is not None:
        support_z, source = float(config.support_z_m), "given"
    elif abs(lowest) <= config.support_search_m:
        support_z, source = 0.0, "world z = 0"
    else:
        support_z, source = lowest, "lowest object point"
    positions, depth = separate(objects, support_z, config)
    moved = tuple(
        replace(
            body,
            position_m=position,
            displacement_m=body.displacement_m + (position - body.position_m),
        )
        for body, position in zip(objects, positions, strict=True)
    )
    return SceneBodies(support_z, source, moved, depth)


def separate(
    objects: Sequence[ObjectBody], support_z_m: float, config: ExportConfig
) -> tuple[np.ndarray, float]:
    """Start positions (N, 3) with no contact deeper than the tolerance (module doc), and the
    deepest contact left (m, 0 if none)."""
    import mujoco

    positions = np.array([body.position_m for body in objects], dtype=np.float64).reshape(-1, 3)
    if not objects:
        return positions, 0.0
    xml, assets = mjcf_document(objects, support_z_m, config, collision_only=True, embed=True)
    model = mujoco.MjModel.from_xml_string(xml, assets)
    data = mujoco.MjData(model)
    body_of_geom = np.full(model.ngeom, -1, dtype=np.int64)
    for index, body in enumerate(objects):
        for geom in range(model.ngeom):
            if model.geom_bodyid[geom] == model.body(body.name).id:
                body_of_geom[geom] = index
    address = [int(model.jnt_qposadr[model.body(body.name).jntadr[0]]) for body in objects]
    push = 2e-5  # beyond the depth, so that the contact is gone rather than just touching
    depth = 0.0
    for _ in range(config.separation_iterations + 1):
        for index, start in enumerate(address):
            data.qpos[start : start + 3] = positions[index]
        mujoco.mj_forward(model, data)
        moves: dict[int, tuple[float, np.ndarray]] = {}
        depth = 0.0
        for contact in data.contact[: data.ncon]:
            penetration = -float(contact.dist)
            if penetration <= 0:
                continue
            depth = max(depth, penetration)
            if penetration <= config.separation_tolerance_m:
                continue
            first, second = (int(body_of_geom[g]) for g in contact.geom)
            normal = np.asarray(contact.frame[:3], dtype=np.float64)  # from geom 1 to geom 2
            if first < 0 and second < 0:
                continue
            if first < 0:
                mover, direction = second, normal
            elif second < 0:
                mover, direction = first, -normal
            elif positions[second, 2] >= positions[first, 2]:
                mover, direction = second, normal
            else:
                mover, direction = first, -normal
            if penetration > moves.get(mover, (0.0, None))[0]:
                moves[mover] = (penetration, direction)
        if not moves:
            break
        for mover, (penetration, direction) in moves.items():
            positions[mover] += direction * (penetration + push)
    return positions, depth
