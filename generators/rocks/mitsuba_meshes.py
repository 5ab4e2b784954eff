"""Rock buffers as ordinary Mitsuba meshes (no ``shapegroup``/``instance``).

Measured on Mitsuba 3.9.1 with 5,000 rocks (see ``design.md``): ``shapegroup``
plus ``instance`` took 434-546 s and 8.9 GB to set up, flat meshes with baked
transforms 0.97 s and 0.9 GB. So every buffer of :func:`.instancing.instance_buffers`
(rocks merged per tile, world-space vertices) becomes one ``mi.Mesh``, with
the rocks' object-space positions in the ``vertex_objp`` attribute that the
``triplanar`` BSDF reads when its ``space`` is ``'object'``: a rock's texture
stays on the rock.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from arches_render.materials.triplanar import OBJP_ATTRIBUTE

__all__ = ["rock_meshes_mitsuba"]


def rock_meshes_mitsuba(buffers: list, bsdf, name: str = "rocks") -> list:
    """One ``mi.Mesh`` per buffer.

    Parameters
    ----------
    buffers : list of dict
        From :func:`.instancing.instance_buffers`.
    bsdf : mi.BSDF
        Shared by all meshes.
    name : str
        Prefix of the mesh ids.

    Returns
    -------
    list of mi.Mesh
    """
    out = []
    for i, b in enumerate(buffers):
        props = mi.Properties()
        props["bsdf"] = bsdf
        mesh = mi.Mesh(f"{name}_{i}", len(b["positions"]), len(b["faces"]), props, has_vertex_normals=True)
        # ``add_attribute`` takes a Python sequence, converted float by float (70 ms for
        # 250k vertices from an mi.Float): it declares the attribute with zeros (a list,
        # the fastest sequence), and the buffer itself goes in through ``traverse``.
        mesh.add_attribute(OBJP_ATTRIBUTE, 3, [0.0] * (3 * len(b["positions"])))
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(b["positions"].ravel())
        params["faces"] = mi.UInt32(b["faces"].ravel())
        params["vertex_normals"] = mi.Float(b["normals"].ravel())
        params[OBJP_ATTRIBUTE] = mi.Float(b["objp"].ravel())
        params.update()
        out.append(mesh)
    dr.eval()
    return out
