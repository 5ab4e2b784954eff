"""An ordered list of editing operations applied to material stacks (scriptable tools).

Each operation is a plain dict with a ``tool`` and that tool's parameters, so the
same list drives the tools from Python and from scene files
(:mod:`~.scene_nodes`). As in the paper's architecture (section 3.1, figure 2) the
granular layers are stabilized after every editing step unless the operation says
``stabilize = False``.

===========  ============================================================================
tool         keys (``[ ]`` optional, default)
===========  ============================================================================
sculpt       at = [x, y, z], radius, [mode = "add" | "remove"], [delta = radius / 2],
             [material = "bedrock"]
sweep        path = [[x, y, z], ...] (>= 2), profile = [[u, v], ...] (>= 3) or one
             profile per path point, [mode = "tunnel" | "crack"], [scale = [..]],
             [depth_offset = 0], [roughness = 0]
deposit      center = [x, y], radius, amount, [material = "sand" | "rock"], [z = top]
erode        center = [x, y, z], radius (number or 3 numbers), [rho = 0.5],
             [mode = "collapse" | "surface"], [depth = cell], [roughness = 0]
stabilize    (no keys): stabilize now
===========  ============================================================================

Every operation also takes ``[stabilize = true]``; the ``seed`` of an operation is
the list's seed plus its index, so a list is deterministic.
"""

from __future__ import annotations

from .material_stacks import MaterialStacks

# The tools (numba kernels: 0.14 s to import) are imported when an operation runs, not
# by every process that reads the scene node types (which import this module).

TOOLS = ("sculpt", "sweep", "deposit", "erode", "stabilize")


def apply_operation(stacks: MaterialStacks, op: dict, seed=0, angles=None, sigma=None):
    """Apply one operation (see module table).

    Parameters
    ----------
    stacks : MaterialStacks
    op : dict
        ``{'tool': name, **parameters}``.
    seed : int
        Seed of the operation's noise.
    angles : dict, optional
        Angles of repose for the stabilization (material id -> degrees).
    sigma : float, optional
        Kernel half-side of the field used by ``sculpt``.

    Returns
    -------
    (MaterialStacks, dict)
        New stacks and a log entry (``tool``, plus ``deposited``/``eroded`` quanta and
        stabilization ``sweeps`` where relevant).
    """
    op = dict(op)
    tool = op.pop("tool", None)
    if tool not in TOOLS:
        raise ValueError(f"unknown tool {tool!r} (allowed: {', '.join(TOOLS)})")
    settle = op.pop("stabilize", True)
    log = {"tool": tool}
    try:
        stacks, log = _run(stacks, tool, op, log, seed, sigma)
    except TypeError as exc:   # an unknown or missing parameter
        raise ValueError(f"{tool}: {exc}") from None
    if settle or tool == "stabilize":
        from .stabilization import stabilize
        stacks, stats = stabilize(stacks, angles)
        log["sweeps"] = stats["sweeps"]
    return stacks, log


def _run(stacks, tool, op, log, seed, sigma):
    from .deposit import deposit
    from .erosion import erode
    from .sculpt import sculpt
    from .sweep import sweep
    if tool == "sculpt":
        stacks = sculpt(stacks, sigma=sigma, **op)
    elif tool == "sweep":
        stacks = sweep(stacks, seed=seed, **op)
    elif tool == "deposit":
        stacks, log["deposited"] = deposit(stacks, **op)
    elif tool == "erode":
        stacks, log["eroded"] = erode(stacks, seed=seed, **op)
    elif op:
        raise ValueError(f"stabilize takes no parameters (got {', '.join(op)})")
    return stacks, log


def apply_operations(stacks: MaterialStacks, ops, seed=0, angles=None, sigma=None, progress=None):
    """Apply a list of operations in order (see :func:`apply_operation`).

    Returns
    -------
    (MaterialStacks, list of dict)
    """
    log = []
    for k, op in enumerate(ops):
        stacks, entry = apply_operation(stacks, op, seed=seed + k, angles=angles, sigma=sigma)
        log.append(entry)
        if progress is not None:
            progress(k + 1, len(ops))
    return stacks, log
