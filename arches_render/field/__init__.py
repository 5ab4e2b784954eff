"""The implicit field language: one construction tree for generators and renderer.

See :mod:`arches_render.field.node` for the protocol (``eval``, ``bounds``,
``lipschitz``) and the sign convention (``f > 0`` inside matter).
"""

from .heightfield import Heightfield
from .node import Node, evaluate, gradient
from .operators import Blend, Difference, Intersection, SmoothIntersection, Union
from .primitive_set import CapsuleSet
from .primitives import Box, Capsule, Plane, Sphere
from .transforms import Transform
from .warps import Displace, DomainWarp, Noise

__all__ = ["Node", "evaluate", "gradient", "Sphere", "Box", "Capsule", "Plane", "Heightfield",
           "Union", "Intersection", "Difference", "Blend", "SmoothIntersection", "Transform",
           "Noise", "Displace", "DomainWarp", "CapsuleSet"]
