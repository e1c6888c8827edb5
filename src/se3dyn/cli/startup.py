"""What the ``se3dyn`` command needs in its process before the package loads (imported first by
:mod:`se3dyn.cli`; it does nothing unless ``sys.argv[0]`` is the ``se3dyn`` command)."""


def prepare_process() -> None:
    """The ``se3dyn`` command only (not ``import se3dyn.cli`` in a program), before numpy loads
    (``import se3dyn`` loads nothing: its names load on first use):

    * numpy's OpenBLAS starts its worker threads at import, and each spins (``sched_yield``)
      for 2^28 cycles, ~0.1 s, before it sleeps: on a machine whose cores are busy that cost
      the command's start-up 30-40 ms of CPU and up to 0.15 s of wall time (numpy's import
      0.07 -> 0.23 s at load 3 on 2 cores). ``OPENBLAS_THREAD_TIMEOUT=4`` (2^4 cycles, unless
      set) puts them to sleep at once; the number of threads, and so every result, is the
      same, and a BLAS call that uses them wakes them (the engine does not use BLAS). The
      processes the command starts (sweep workers) inherit the setting.
    * The cyclic garbage collector pauses while the modules load (their objects all live
      on: the collections of the start-up only walked them, 10-15 ms of CPU); once they are
      loaded, ``se3dyn.cli.commands`` freezes what exists (``gc.freeze``: never walked again) and
      resumes it, before the simulation. At exit, the interpreter's last collections walk
      every object (50-80 ms of wall time): the objects are frozen first (the last atexit
      handler; all of them go with the process). The handlers registered later, the
      teardown of the modules and the finalizers of the objects that no cycle holds run as
      before. Not for ``sweep``: dask shuts its machinery down as usual.
    * Ctrl-C while the package loads prints one line and exits with 130, no traceback, and
      SIGTERM likewise with 143 (:func:`se3dyn.cli.commands.main` installs its own handlers
      once it runs).
    """
    import os
    import sys

    if os.path.basename(sys.argv[0] if sys.argv else "") not in ("se3dyn", "se3dyn.exe"):
        return
    os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")
    if "sweep" not in sys.argv[1:2]:
        import atexit
        import gc

        global GC_PAUSED
        GC_PAUSED = gc.isenabled()
        gc.disable()  # se3dyn.cli.commands resumes it
        atexit.register(gc.freeze)  # registered first: runs last

    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupted(signum, frame):
        if signum == signal.SIGTERM:
            os.write(2, b"se3dyn: error: terminated\n")
            os._exit(143)
        os.write(2, b"se3dyn: error: interrupted\n")
        os._exit(130)

    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, interrupted)
        if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
            signal.signal(signal.SIGTERM, interrupted)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        pass


GC_PAUSED = False  # by prepare_process, until se3dyn.cli.commands resumes the collector
prepare_process()
