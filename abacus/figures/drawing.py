"""One interface for drawing figures: :meth:`Drawing.submit` a job, :meth:`Drawing.wait` for it.

A job is a drawing function of :mod:`abacus.figures` (a module-level function, so that it can be
sent to another process) and its arguments: plain data — arrays, numbers, the folder to write
into — in, the paths of the files it wrote out.

:class:`Drawing` (the default) draws each job in this process when it is submitted.
:class:`PoolDrawing` hands the jobs to a standard-library process pool
(:class:`concurrent.futures.ProcessPoolExecutor`, start method "spawn": fresh interpreters,
never a fork of this process), whose workers import matplotlib and get ready to draw as soon as
the pool is made, so that a command goes on computing while its figures are drawn on the cores
it leaves idle.
``abacus run`` uses the pool where there is a core to spare (docs/performance.md, "End to end").

Either way a failed job raises its error from :meth:`~Drawing.wait`, and leaving the ``with``
block on an error cancels what was not begun and waits for what was: once it is left, nothing
writes into the jobs' folders any more.

Examples
--------
>>> from abacus.figures.drawing import Drawing
>>> from abacus.figures.plots import draw_counts_figure
>>> with Drawing() as drawing:                                     # doctest: +SKIP
...     drawing.submit(draw_counts_figure, counts, "figures")
...     paths = drawing.wait()
"""
from __future__ import annotations

from concurrent.futures import Future

__all__ = ["Drawing", "PoolDrawing"]


class Drawing:
    """Draws each job in this process, when it is submitted."""

    def __init__(self):
        self._futures: list[Future] = []

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        self.close(cancel=kind is not None)
        return False

    def submit(self, job, *args) -> Future:
        """Draw ``job(*args)``; its result (or error) is the returned future's."""
        future: Future = Future()
        try:
            future.set_result(job(*args))
        except Exception as error:      # raised by wait(), as a pool's would be
            future.set_exception(error)
        self._futures.append(future)
        return future

    def wait(self, futures=None) -> list:
        """The results of ``futures`` (default: every job submitted so far), in order, once all
        are drawn; raises the first error among them."""
        futures = list(self._futures if futures is None else futures)
        results = [f.exception() for f in futures]      # waits for every one of them
        for f, error in zip(futures, results):
            if error is not None:
                raise error
        return [f.result() for f in futures]

    def close(self, *, cancel: bool = False):
        """Nothing is left drawing once this returns (``cancel``: jobs not begun are dropped)."""


class PoolDrawing(Drawing):
    """Draws the jobs in ``workers`` processes of a standard-library pool ("spawn").

    The workers start at once and import matplotlib while this process goes on. They ignore
    SIGINT (a Ctrl-C reaches the whole process group: the command handles it and closes the
    pool), from their first instruction: they are started with SIGINT blocked, as the standard
    library starts its resource tracker, and unblock it once they ignore it. They end when
    this process ends, even killed (they watch :func:`multiprocessing.parent_process`'s
    sentinel). Their warnings are not shown: a figure's are not the command's.
    """

    def __init__(self, workers: int = 1):
        import multiprocessing
        import signal
        from concurrent.futures import ProcessPoolExecutor
        super().__init__()
        self.workers = max(1, int(workers))
        self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=_start_worker)
        self._open = True
        mask = hasattr(signal, "pthread_sigmask")
        before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if mask else None
        try:
            for _ in range(self.workers):   # one process started per job while none is idle
                self._pool.submit(_ready)
        except BaseException:
            self.close(cancel=True)
            raise
        finally:
            if mask:    # a SIGINT that came meanwhile is delivered here, to this process
                signal.pthread_sigmask(signal.SIG_SETMASK, before)

    def submit(self, job, *args) -> Future:
        future = self._pool.submit(job, *args)
        self._futures.append(future)
        return future

    def close(self, *, cancel: bool = False):
        """Without ``cancel`` (every job waited for): the workers are told to end, and this
        process does not wait for them to tear down. With ``cancel``: jobs not begun are dropped
        and the ones being drawn are waited for."""
        if self._open:
            self._open = False
            self._pool.shutdown(wait=cancel, cancel_futures=cancel)


def _ready() -> None:
    """A job that draws nothing: submitted once per worker, it starts them all."""


def _start_worker() -> None:
    """A pool worker's start: SIGINT left to the command, an end with it, matplotlib loaded and
    ready to draw (:func:`abacus.figures.plots.prepare`)."""
    import signal
    import warnings
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # a pending one is dropped with it
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    warnings.simplefilter("ignore")
    _end_with_parent()
    import matplotlib
    matplotlib.use("Agg")

    # what the jobs import and their first figure's font and encoder, loaded before the first
    # job comes (while the command simulates): ≈ 0.4 s less on the run's path after it
    from abacus.figures.plots import prepare
    prepare()
    # what is loaded now lives as long as the worker: out of the collector's sight, a figure's
    # garbage collections do not walk it again (≈ 5 % of the drawing, measured on the run's jobs)
    import gc
    gc.collect()
    gc.freeze()


def _end_with_parent() -> None:
    """End this worker when the process that made the pool ends, however it ends: its
    sentinel (:func:`multiprocessing.parent_process`) becomes ready, and a thread that waits
    for it ends the worker with SIGTERM (left at its default action in a worker)."""
    import multiprocessing
    import os
    import signal
    import threading
    from multiprocessing.connection import wait

    parent = multiprocessing.parent_process()
    if parent is None:      # pragma: no cover - not started by multiprocessing
        return

    def watch():
        wait([parent.sentinel])
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, name="abacus-parent-watch", daemon=True).start()
