"""``python -m homogenize.cli``: the ``mapsim`` command."""
import sys

from homogenize.cli import main

sys.exit(main())
