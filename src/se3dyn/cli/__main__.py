"""``python -m se3dyn.cli ...``: the ``se3dyn`` command."""

import sys

from se3dyn.cli.commands import main

sys.exit(main())
