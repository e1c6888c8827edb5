"""The ``se3dyn`` command (entry point :func:`se3dyn.cli.commands.main`, the top layer).

What the command needs in its process before the package loads lives here, with the command,
and runs only when this package is imported as the command (``sys.argv[0]`` is ``se3dyn``):
``import se3dyn`` in a program changes no process state.
"""

from se3dyn.cli import startup  # first: before numpy and the engine load
from se3dyn.cli.commands import main  # noqa: E402

__all__ = ["main", "startup"]
