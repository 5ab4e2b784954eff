"""arches-render: volumetric terrain as one implicit construction tree, rendered by Mitsuba 3.

Conventions kept by every module
--------------------------------
* World space is **Z-up**, right-handed, in metres. Heightfields are ``z = h(x, y)``;
  Mitsuba's ``sunsky`` is Z-up already, cameras use ``up = [0, 0, 1]``.
* A field ``f`` is **positive inside matter**, zero on the surface and negative in
  air. Every node reports a guaranteed Lipschitz bound ``L`` (``|f(a) - f(b)| <=
  L |a - b|``), so ``-f(p) / L`` is a safe sphere-tracing step from ``p`` in air.
* Field values are in metres wherever a node can keep them so (signed distances for
  primitives, ``h(x, y) - z`` for heightfields), so blend radii are in metres too.
* Fields are evaluated by Dr.Jit on ``mi.Point3f`` batches; the same code serves the
  sphere tracer (inside ``dr.while_loop``) and the generators (numpy in, numpy out,
  through :func:`arches_render.field.evaluate`).

The variant is chosen by :func:`arches_render.backend.set_variant` (``llvm_ad_rgb``
by default); call it (or :func:`arches_render.backend.variant`) before touching
``mitsuba`` types. Importing this package points Dr.Jit at a usable libLLVM
(:func:`arches_render.backend.prepare_llvm`), so import ``arches_render`` before
``drjit``; every module of the package may then import ``drjit`` at its top.
"""

from .backend import prepare_llvm

__version__ = "0.1.0"

# Before any module of ours imports drjit: Dr.Jit loads libLLVM on import.
prepare_llvm()
