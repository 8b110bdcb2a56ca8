"""Figures drawn by a helper process while the command computes.

matplotlib draws on one core and holds the GIL; abacus' physics and processing leave part of
the machine idle (start-up, single-threaded stretches, writing the dataset). A command that
draws figures starts :class:`FigureWorker` first: the helper imports matplotlib and warms its
fonts while the command imports and simulates, then draws the jobs it is sent — figures of the
data of :mod:`abacus.figures.plots` and :mod:`abacus.figures.beams` (plain arrays, pickled over
a pipe) — in order, into the folders it is told (the command's staged temporaries), and answers
each with the files written.

It runs at the command's priority: on two cores, drawing beside the physics (and slowing it)
ends sooner than drawing only in its gaps and leaving a serial tail (measured: a lower priority,
or a second helper, made the run no faster). When figures queue up (the counts' figures, sent
together — one message, :meth:`FigureWorker.submit_together` — once the numbers exist and drawn
while the command only writes and waits) the helper forks copies of itself, matplotlib already
imported and warm, to draw them side by side, one per spare core. Its reading thread only
takes the jobs' bytes off the pipe; the main thread unpickles them, after its own imports.
The helper never outlives the command: it ignores SIGINT (the command handles Ctrl-C and ends
it), is killed with the command (``PR_SET_PDEATHSIG`` on Linux, as are its copies with it) and
by :func:`stop_all`, which the CLI's exit path calls before it removes the
temporaries the helper may be writing into; it leads its own process group, so that one signal
ends it and its copies together. Answers are single writes of at most ``PIPE_BUF`` bytes
(file names, not paths), which the helper and its copies can share a pipe with.
A job that fails comes back as :class:`FigureError` with the helper's traceback.
"""
from __future__ import annotations

import os
import subprocess
import sys

__all__ = ["FigureWorker", "FigureError", "stop_all", "spare_drawers", "JOBS"]

#: what a helper can be asked to draw: function(data, outdir) -> the module that defines it
JOBS = {"draw_image_figures": "abacus.figures.plots", "draw_detection_figure": "abacus.figures.plots",
        "draw_detection_figures": "abacus.figures.plots", "draw_counts_figure": "abacus.figures.plots",
        "plot_beam_figures": "abacus.figures.beams"}

#: workers of this process still running (for :func:`stop_all`)
_LIVE: set = set()


class FigureError(RuntimeError):
    """A figure the helper process could not draw (its traceback in the message)."""


def stop_all() -> None:
    """Kill every helper of this process (interrupt and exit paths)."""
    for worker in list(_LIVE):
        worker.kill()


class FigureWorker:
    """A helper process that draws figures; use as a context manager.

    Examples
    --------
    >>> with FigureWorker() as figures:                      # doctest: +SKIP
    ...     ticket = figures.submit("draw_counts_figure", data, folder)
    ...     paths = figures.result(ticket)
    """

    def __init__(self, timeout_s: float = 600.0):
        from multiprocessing.connection import Connection

        self.timeout_s = float(timeout_s)
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        env = dict(os.environ)
        for key in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
            env[key] = "1"              # it draws; the command's threads have the cores
        env["MPLBACKEND"] = "Agg"
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "abacus.cli.figure_worker", str(to_child_r), str(from_child_w)],
                pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, close_fds=True,
                start_new_session=True)     # its own process group: it and its forked copies
        finally:
            os.close(to_child_r)
            os.close(from_child_w)
        self._send = Connection(to_child_w, readable=False)
        self._recv = Connection(from_child_r, writable=False)
        self._next = 0
        self._done: dict = {}
        self._folder: dict = {}
        _LIVE.add(self)

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        if kind is None:
            self.close()
        else:
            self.kill()
        return False

    def submit(self, job: str, data, outdir) -> int:
        """Queue a drawing; returns a ticket for :meth:`result`."""
        return self.submit_together([(job, data, outdir)])[0]

    def submit_together(self, jobs) -> list[int]:
        """Queue drawings, ``(job, data, outdir)`` each, that reach the helper as one message:
        it finds them all waiting and draws them side by side (forked copies, one per spare
        core), where jobs sent one by one could find the second still on its way and be drawn
        one after the other. Returns their tickets, in order."""
        jobs = list(jobs)
        if not jobs:
            return []
        for job, _, _ in jobs:
            if job not in JOBS:
                raise ValueError(f"unknown figure job {job!r}; accepted: {', '.join(JOBS)}")
        batch = [(self._next + k, job, data, str(outdir)) for k, (job, data, outdir) in enumerate(jobs)]
        self._next += len(batch)
        try:
            self._send.send(batch)
        except OSError:
            raise self._died() from None
        for ticket, _, _, outdir in batch:
            self._folder[ticket] = outdir
        return [ticket for ticket, *_ in batch]

    def result(self, ticket: int) -> list:
        """The paths the job ``ticket`` wrote (waits for it); raises :class:`FigureError`."""
        while ticket not in self._done:
            try:
                if not self._recv.poll(self.timeout_s):
                    self.kill()
                    raise FigureError(f"the figure process drew nothing for {self.timeout_s:g} s")
                got, ok, value = self._recv.recv()
            except (EOFError, OSError):
                raise self._died() from None
            self._done[got] = (ok, value)
        ok, value = self._done.pop(ticket)
        folder = self._folder.pop(ticket)
        if not ok:
            raise FigureError(value)
        return [os.path.join(folder, name) for name in value]

    def _died(self) -> FigureError:
        code = self._proc.poll()
        self.kill()
        return FigureError(f"the figure process ended unexpectedly (exit status {code})")

    def close(self):
        """Let the helper finish and end (after every :meth:`result` was collected)."""
        if self not in _LIVE:
            return
        _LIVE.discard(self)
        for conn in (self._send, self._recv):
            conn.close()
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()

    def kill(self):
        """End the helper now (it may be writing: call before removing its folders)."""
        import signal
        _LIVE.discard(self)
        if self._proc.poll() is None:
            try:    # the helper and any copy it forked, at once
                os.killpg(self._proc.pid, signal.SIGKILL)
            except OSError:
                self._proc.kill()
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:   # pragma: no cover - the kernel owes us a reap
                pass
        for conn in (self._send, self._recv):
            try:
                conn.close()
            except OSError:
                pass


# ------------------------------------------------------------------------------ the helper
def _die_with_parent():
    """Ask Linux to kill this process when the command that started it ends."""
    try:
        import ctypes
        import signal
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL))          # PR_SET_PDEATHSIG
    except (OSError, AttributeError):               # pragma: no cover - not Linux
        pass
    if os.getppid() == 1:                            # the command already ended
        os._exit(0)


def _warm_up():
    """Load matplotlib's font and renderer once, while the command is still computing."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(1, 1))
    ax.set_title("x")
    fig.canvas.draw()
    plt.close(fig)


def _serve(read_fd: int, write_fd: int):
    import collections
    import pickle
    import queue
    import signal
    import threading
    import warnings
    from multiprocessing.connection import Connection

    signal.signal(signal.SIGINT, signal.SIG_IGN)    # Ctrl-C is the command's to handle
    _die_with_parent()
    warnings.simplefilter("ignore")
    recv = Connection(read_fd, writable=False)
    send = Connection(write_fd, readable=False)
    jobs = queue.SimpleQueue()

    def read():
        # jobs are taken off the pipe as they come, so the command never waits on a full pipe
        # while a figure is being drawn; as bytes: unpickling imports numpy, which must not
        # happen here while the main thread imports matplotlib (two threads importing numpy
        # at once can find it half-initialised: ImportError)
        while True:
            try:
                jobs.put(recv.recv_bytes())
            except (EOFError, OSError):
                jobs.put(None)
                return

    threading.Thread(target=read, daemon=True).start()
    import matplotlib
    matplotlib.use("Agg")
    import abacus.figures.plots  # noqa: F401  (the figures of every run: loaded before they are asked for)
    _warm_up()
    copies: set = set()      # pids of the forked copies still drawing
    most = spare_drawers()
    waiting = collections.deque()   # jobs of the batches taken off the queue, not yet drawn
    while True:
        if not waiting:
            batch = jobs.get()
            if batch is None:
                # the command is done with it: every answer is sent, nothing is left to flush,
                # and tearing matplotlib's interpreter down would only keep the command waiting
                _reap(copies, wait=True)
                os._exit(0)
            waiting.extend(pickle.loads(batch))
            if not waiting:
                continue
        _reap(copies, wait=False)
        ticket, job, data, outdir = waiting.popleft()
        if (waiting or not jobs.empty()) and len(copies) < most:
            # more figures wait than this process draws at once (the counts after the numbers):
            # a forked copy, matplotlib already warm, draws this one beside it
            try:
                pid = os.fork()
            except OSError:
                pid = None
            if pid == 0:
                try:
                    _die_with_parent()
                    _answer(send, _draw(job, ticket, data, outdir))
                finally:
                    os._exit(0)
            if pid is not None:
                copies.add(pid)
                continue
        _answer(send, _draw(job, ticket, data, outdir))


def spare_drawers() -> int:
    """Forked copies that may draw at once: the cores beyond this helper's (at most 3)."""
    from processing.base.resources import usable_cores
    return min(3, usable_cores() - 1)


def _reap(copies: set, *, wait: bool):
    """Collect the forked copies that ended (all of them with ``wait``)."""
    for pid in list(copies):
        try:
            done, _ = os.waitpid(pid, 0 if wait else os.WNOHANG)
        except ChildProcessError:
            done = pid
        if done:
            copies.discard(pid)


def _draw(job, ticket, data, outdir):
    """(ticket, True, names of the files written in ``outdir``) or (ticket, False, the error)."""
    import importlib
    import traceback
    from pathlib import Path
    try:
        if job not in JOBS:
            raise ValueError(f"unknown figure job {job!r}")
        out = getattr(importlib.import_module(JOBS[job]), job)(data, outdir)
        return ticket, True, [Path(p).name for p in (out if isinstance(out, list) else [out])]
    except Exception:   # the command reports it (one line, traceback in its log)
        return ticket, False, f"{job}: {traceback.format_exc(limit=8)}"


#: the most bytes a pipe takes in one write without interleaving it with another's (POSIX ≥ 512)
_PIPE_BUF = getattr(__import__("select"), "PIPE_BUF", 512)


def _answer(send, message):
    """Send one answer in one write of at most PIPE_BUF bytes: the helper and its forked copies
    share the pipe, and such writes are never interleaved (an error's text is shortened to fit,
    keeping its end, which says why)."""
    import pickle
    ticket, ok, value = message
    payload = pickle.dumps(message)
    while len(payload) + 4 > _PIPE_BUF and not ok and len(value) > 1:
        value = "…" + value[-(len(value) // 2):]
        payload = pickle.dumps((ticket, ok, value))
    send.send_bytes(payload)


if __name__ == "__main__":
    _serve(int(sys.argv[1]), int(sys.argv[2]))
