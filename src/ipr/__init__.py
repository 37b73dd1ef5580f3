"""ipr: complete 3D models of unknown rigid objects in clutter by inverse physics reasoning.

The method is Song & Boularias, "Inferring 3D Shapes of Unknown Rigid Objects in Clutter through
Inverse Physics Reasoning", RA-L 2018. Units are metres and radians; the world frame is z-up with
gravity along -z. Millimetres appear only at the BOP file boundary.
"""

from ipr.gl import select_gl_backend

# MuJoCo reads MUJOCO_GL when it is first imported, so the backend is chosen before anything else.
select_gl_backend()

__version__ = "0.1.0"
