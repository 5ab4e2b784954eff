"""Choose the Mitsuba variant and make sure Dr.Jit's LLVM backend can work.

Dr.Jit's LLVM backend loads ``libLLVM`` at import time. LLVM 14 and 15 accept
the library but crash later, while compiling a kernel, with
``Cannot select: fminimum``; that takes the process down with a backtrace deep
inside LLVM. We therefore

1. point ``DRJIT_LIBLLVM_PATH`` at the newest libLLVM we can find (>= 16) when
   the user has not chosen one, before ``drjit`` is imported
   (:func:`prepare_llvm`, run when the ``arches_render`` package is imported, so
   every module of ours may import ``drjit`` at its top), and
2. read ``/proc/self/maps`` after the import to learn which libLLVM was really
   loaded, and stop with :class:`BackendError` (a one-line message that says
   how to install ``libllvm19``) when it is missing or too old.

``cuda_ad_rgb`` is used when ``ARCHES_VARIANT`` asks for it or when it is the
only variant that works; ``llvm_ad_rgb`` is the default everywhere.

This module is a leaf: it imports nothing of arches-render. Our Python plugins
(``implicit_path``, ``triplanar``) are registered where rendering starts
(:func:`arches_render.render.plugins.ensure_registered`), not here, and
:func:`variant_class` binds a plugin class to the variant chosen at run time.
"""

from __future__ import annotations

import contextlib
import glob
import os
import re

MIN_LLVM_MAJOR = 16
INSTALL_HINT = (
    "install a recent libLLVM (Debian/Ubuntu: 'sudo apt-get install libllvm19') "
    "or set DRJIT_LIBLLVM_PATH to a libLLVM.so of version 16 or newer"
)
_LIB_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
             "/usr/local/lib")

_variant: str | None = None


class BackendError(RuntimeError):
    """The rendering backend cannot run on this machine (message is user-facing)."""


def llvm_major_from_path(path: str) -> int | None:
    """Major LLVM version encoded in a library file name.

    Parameters
    ----------
    path : str
        A path such as ``/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1`` or
        ``libLLVM.so.19.1``.

    Returns
    -------
    int or None
        The major version, or ``None`` when the name carries none.
    """
    name = os.path.basename(path)
    m = re.match(r"libLLVM[-.]?(?:so\.)?(\d+)", name)
    return int(m.group(1)) if m else None


def find_newest_libllvm(dirs=_LIB_DIRS) -> str | None:
    """Return the path of the newest ``libLLVM`` (major >= 16) in ``dirs``, if any."""
    best: tuple[int, str] | None = None
    for d in dirs:
        for path in glob.glob(os.path.join(d, "libLLVM*.so*")):
            major = llvm_major_from_path(path)
            if major is not None and major >= MIN_LLVM_MAJOR and (best is None or major > best[0]):
                best = (major, path)
    return best[1] if best else None


def loaded_libllvm() -> list[str]:
    """Paths of the libLLVM libraries mapped into this process."""
    try:
        with open("/proc/self/maps") as f:
            return sorted({line.split()[-1] for line in f if "libLLVM" in line})
    except OSError:  # not Linux: nothing to inspect
        return []


def check_llvm(loaded: list[str]) -> None:
    """Raise :class:`BackendError` unless ``loaded`` holds a usable libLLVM."""
    if not loaded:
        raise BackendError(f"Dr.Jit found no libLLVM on this machine: {INSTALL_HINT}.")
    majors = [llvm_major_from_path(p) for p in loaded]
    bad = [(p, m) for p, m in zip(loaded, majors) if m is not None and m < MIN_LLVM_MAJOR]
    if bad:
        path, major = bad[0]
        why = "crashes with 'Cannot select fminimum'" if major == 15 else "is too old for Dr.Jit"
        raise BackendError(f"Dr.Jit loaded LLVM {major} ({path}), which {why}: {INSTALL_HINT}.")


def prepare_llvm(name: str | None = None) -> None:
    """Point Dr.Jit at the newest libLLVM >= 16 unless the user chose one.

    Must run before ``drjit`` is first imported (Dr.Jit loads libLLVM then); the
    ``arches_render`` package calls it on import.

    Parameters
    ----------
    name : str, optional
        The variant that will be used; default ``$ARCHES_VARIANT`` or
        ``'llvm_ad_rgb'``. Only LLVM variants need a libLLVM.
    """
    name = name or os.environ.get("ARCHES_VARIANT", "llvm_ad_rgb")
    if name.startswith("llvm") and "DRJIT_LIBLLVM_PATH" not in os.environ:
        newest = find_newest_libllvm()
        if newest:
            os.environ["DRJIT_LIBLLVM_PATH"] = newest


def set_variant(name: str | None = None) -> str:
    """Select the Mitsuba variant once per process and return its name.

    Parameters
    ----------
    name : str, optional
        ``'llvm_ad_rgb'`` or ``'cuda_ad_rgb'``; default: ``$ARCHES_VARIANT`` or
        ``'llvm_ad_rgb'``.

    Returns
    -------
    str
        The active variant.

    Raises
    ------
    BackendError
        When the LLVM backend would crash (libLLVM missing or older than 16).
    """
    global _variant
    name = name or os.environ.get("ARCHES_VARIANT", "llvm_ad_rgb")
    if _variant == name:
        return name
    prepare_llvm(name)  # in case drjit is not imported yet (an explicit name)
    # Imported here, not at the top: importing Dr.Jit loads libLLVM, which must
    # wait until prepare_llvm has chosen it (and a backend error is reported by
    # the caller, inside its error handling).
    import drjit as dr  # noqa: F401  (loads libLLVM)
    import mitsuba as mi

    if name.startswith("llvm"):
        check_llvm(loaded_libllvm())
    if name not in mi.variants():
        raise BackendError(f"Mitsuba variant '{name}' is not available; choose one of {mi.variants()}.")
    mi.set_variant(name)
    if dr.thread_count() < MIN_IO_THREADS:  # a one-core machine (io_threads)
        dr.set_thread_count(MIN_IO_THREADS)
    _variant = name
    return name


#: The fewest Dr.Jit threads with which Mitsuba's EXR input and output can run (:func:`io_threads`).
MIN_IO_THREADS = 2


@contextlib.contextmanager
def io_threads():
    """Hold Dr.Jit's thread pool at :data:`MIN_IO_THREADS` or more inside this block.

    Mitsuba reads and writes EXR files with OpenEXR, whose tasks run on Dr.Jit's thread
    pool while the calling thread waits for them: with a pool of one thread nothing
    runs them, and the process hangs for ever in ``mi.Bitmap`` (measured: an
    environment map read by a scene load on a one-core machine, or in a render job
    given one thread, as two Dask workers on two cores are). Loads of scene files go
    through this; renders may then run on one thread (the sweep's Debug renders must).
    """
    import drjit as dr
    n = dr.thread_count()
    if n >= MIN_IO_THREADS:
        yield
        return
    dr.set_thread_count(MIN_IO_THREADS)
    try:
        yield
    finally:
        dr.set_thread_count(n)


def variant() -> str:
    """The active variant, selecting the default one on first use."""
    return _variant or set_variant()


_BOUND: dict = {}


def variant_class(name: str, impl: type, base: str) -> type:
    """``impl`` as a class ``name`` deriving from the active variant's ``mi.<base>``.

    Mitsuba's plugin base classes (``mi.BSDF``, ``mi.SamplingIntegrator``) exist per
    variant, and the variant is chosen at run time, so a plugin is written as a
    plain class ``impl`` and bound here. nanobind types take a single base, so the
    body of ``impl`` is copied in, not mixed in: methods must call the base as
    ``mi.<base>.__init__(self, props)``, never ``super()``.

    Parameters
    ----------
    name : str
        Name of the bound class (``'TriplanarBSDF'``).
    impl : type
        The plugin's implementation.
    base : str
        Name of the Mitsuba base class, e.g. ``'BSDF'``.

    Returns
    -------
    type
        The bound class, the same object on every call for one variant.
    """
    import mitsuba as mi  # after set_variant (see the comment there)
    active = mi.variant()
    if active is None:
        raise RuntimeError(f"{name}: select a Mitsuba variant first (arches_render.backend.set_variant())")
    key = (impl, base, active)
    if key not in _BOUND:
        body = {k: v for k, v in vars(impl).items() if k not in ("__dict__", "__weakref__")}
        _BOUND[key] = type(name, (getattr(mi, base),), body)
    return _BOUND[key]
