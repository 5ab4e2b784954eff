"""Render jobs in a child process, so that a native crash is a one-line error, not a lost worker.

A segmentation fault in Mitsuba, Dr.Jit or a kernel they compiled (issue 38: a gather
far outside its array) kills the process it happens in, with no Python exception. In
a Dask worker that process is the worker: its nanny restarts it, the scheduler hands
the task to another worker (``distributed.scheduler.allowed-failures`` times, each
building the scene and compiling its kernels again) and the client finally gets
``KilledWorker``, which names neither the scene, nor the frame or tile, nor the signal.

So a worker renders in a child process of its own, :class:`RenderProcess`, kept
across jobs (its scene cache and compiled kernels serve the next job, as the worker's
own did). When the child dies, the job raises :class:`RenderCrash` in the worker: an
ordinary task error, which Dask does not retry, whose one-line message names the
scene, the frame or tile, and the signal; the next job starts a fresh child. A worker
killed from outside (SIGKILL, the OOM killer) is still Dask's to reschedule; when
Dask gives up, :func:`arches_render.render.distributed.map_jobs` reports it the same
way. :func:`run_isolated` is the task a worker runs.

The child is ``python -m arches_render.render.isolated FD``: it reads jobs from the
socket ``FD`` and answers each (a job, ``forget``, a thread count, a ping) with
``("ok", (rgb, layers))`` or ``("error", exception)`` (:mod:`multiprocessing.connection`
framing, pickles). It leaves when the socket closes, or when its parent dies (it then
belongs to another parent; checked twice a second), so a killed worker leaves no
renderer behind.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection

from .. import faults

__all__ = ["RenderCrash", "RenderProcess", "run_isolated", "render_process", "exit_description"]


class RenderCrash(RuntimeError):
    """A process rendering a job died (by a signal, or exiting) before it answered.

    The message is one line: the job (:meth:`~arches_render.render.jobs.RenderJob.describe`:
    scene, frame or tile, mode) and how the process ended.
    """


def exit_description(returncode: int) -> str:
    """How a process ended, from its ``returncode`` (negative: the signal that killed it).

    Returns
    -------
    str
        ``'died by SIGSEGV (Segmentation fault)'`` or ``'exited with status N'``.
    """
    if returncode < 0:
        try:
            sig = signal.Signals(-returncode)
            return f"died by {sig.name} ({signal.strsignal(sig)})"
        except ValueError:
            return f"died by signal {-returncode}"
    return f"exited with status {returncode}"


class RenderProcess:
    """A child process that renders :class:`~arches_render.render.jobs.RenderJob` s one at a time.

    The child starts on the first job (or :meth:`start`) and lives until :meth:`close`,
    its parent's death, or a crash (the next job starts another). Thread-safe: jobs
    from several threads take turns.

    Parameters
    ----------
    stderr : file or None, optional
        Where the child's standard error goes (default: this process's).
    jit_debug : bool, optional
        Run the child with Dr.Jit's ``Debug`` flag: every gather and scatter checks
        its index and reports one outside its array on the child's standard error
        (``out-of-bounds``), where it would otherwise read or write anywhere.
    """

    def __init__(self, stderr=None, jit_debug: bool = False):
        self._lock = threading.Lock()
        self._proc = None
        self._conn = None
        self._stderr = stderr
        self._jit_debug = bool(jit_debug)

    @property
    def pid(self):
        """The child's process id, or ``None`` while none runs."""
        return self._proc.pid if self._proc is not None and self._proc.poll() is None else None

    def start(self) -> None:
        """Start the child (if none runs) and wait until it has chosen its Mitsuba variant."""
        with self._lock:
            self._ask(("ping",), "start")

    def run(self, job, timeout: float | None = None):
        """Render ``job`` in the child.

        Parameters
        ----------
        job : RenderJob
        timeout : float, optional
            Seconds to wait for the answer; past them the child is killed (a hang is
            an error too). Default: no limit.

        Returns
        -------
        (numpy.ndarray, dict)
            As :func:`arches_render.render.jobs.run_job`.

        Raises
        ------
        RenderCrash
            When the child dies (or times out) before it answers.
        Exception
            What :func:`~arches_render.render.jobs.run_job` raised in the child.
        """
        with self._lock:
            return self._ask(("job", job), job.describe(), timeout)

    def forget(self) -> None:
        """Have the child drop the scenes and descriptions it keeps
        (:func:`~arches_render.render.jobs.clear_cache`), if one runs.

        For a process that renders many scenes one after the other (the scene sweep):
        with earlier scenes still alive, every render in it slows down (a scene's four
        tiny modes 3 s fresh, 25 s after five other scenes, with Dr.Jit's ``Debug`` flag).
        """
        with self._lock:
            if self.pid is not None:
                self._ask(("forget",), "forget")

    def thread_count(self):
        """Dr.Jit's thread count in the child, ``None`` while no child runs."""
        with self._lock:
            return self._ask(("threads",), "thread count") if self.pid is not None else None

    def close(self) -> None:
        """Stop the child (it leaves when its socket closes)."""
        with self._lock:
            self._stop()

    # -- internals -----------------------------------------------------------------
    def _spawn(self) -> None:
        import socket
        ours, theirs = socket.socketpair()
        argv = [sys.executable, "-m", __name__, str(theirs.fileno())] + (["--jit-debug"] if self._jit_debug else [])
        try:
            self._proc = subprocess.Popen(argv, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                          stderr=self._stderr)
        finally:
            theirs.close()
        self._conn = Connection(ours.detach())

    def _ask(self, request, what: str, timeout: float | None = None):
        if self._proc is None or self._proc.poll() is not None:
            self._stop()
            self._spawn()
        try:
            self._conn.send(request)
            status, value = self._receive(timeout)
        except TimeoutError:
            self._proc.kill()
            self._stop()
            raise RenderCrash(f"{what}: the render process gave no answer in {timeout:g} s (killed)") from None
        except (EOFError, OSError):
            code = self._proc.wait()
            self._stop()
            raise RenderCrash(f"{what}: the render process {exit_description(code)}") from None
        if status == "error":
            raise value
        return value

    def _receive(self, timeout):
        # Poll rather than block: should the child leave its socket open in a process of
        # its own, its death must still be seen (never a hang).
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._conn.poll(0.5):
            if self._proc.poll() is not None and not self._conn.poll(0):
                raise EOFError
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError
        return self._conn.recv()

    def _stop(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:  # busy with a job: it would only finish it
                self._proc.kill()
                self._proc.wait()
            self._proc = None


_PROCESS = RenderProcess()


def render_process() -> RenderProcess:
    """This process's :class:`RenderProcess` (the one :func:`run_isolated` uses)."""
    return _PROCESS


def run_isolated(job):
    """Render ``job`` in this process's render child (:class:`RenderProcess`): the task a Dask
    worker runs. Returns and raises as :meth:`RenderProcess.run`."""
    faults.point("render.task")  # test-only kill point (arches_render.faults)
    return _PROCESS.run(job)


# -- the child ---------------------------------------------------------------------
def _leave_with_parent(parent: int) -> None:
    while True:
        if os.getppid() != parent:
            os._exit(0)  # the worker died (a kill): nothing to answer to
        time.sleep(0.5)


def _answer(conn: Connection, request) -> None:
    from .jobs import run_job
    kind = request[0]
    try:
        if kind == "job":
            value = run_job(request[1])
        elif kind == "forget":
            import gc

            from .jobs import clear_cache
            clear_cache()
            gc.collect()  # the Mitsuba scenes and Dr.Jit arrays, now, not whenever
            value = None
        elif kind == "threads":
            import drjit as dr
            value = int(dr.thread_count())
        else:
            value = None
        reply = ("ok", value)
    except Exception as exc:  # the job's error, raised again in the parent
        reply = ("error", _portable(exc))
    conn.send(reply)


def _portable(exc: Exception) -> Exception:
    """``exc`` if the parent can rebuild it from its pickle (an exception whose ``__init__``
    takes other arguments than its ``args`` cannot), else a ``RuntimeError`` with its text."""
    try:
        pickle.dumps(exc)
        rebuild, args = exc.__reduce__()[:2]
        rebuild(*args)  # what unpickling it in the parent calls
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")


def main(argv=None) -> int:
    """The child's loop: answer requests on the socket given as ``argv[0]`` until it closes
    (``--jit-debug``: Dr.Jit's ``Debug`` flag on, see :class:`RenderProcess`)."""
    argv = sys.argv[1:] if argv is None else argv
    conn = Connection(int(argv[0]))
    threading.Thread(target=_leave_with_parent, args=(os.getppid(),), daemon=True).start()
    from ..backend import set_variant
    set_variant()
    if "--jit-debug" in argv:
        import drjit as dr
        dr.set_flag(dr.JitFlag.Debug, True)
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            return 0
        _answer(conn, request)


if __name__ == "__main__":
    sys.exit(main())
