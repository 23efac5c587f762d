"""``python -m georeg_app``: the ``georeg`` command line."""
import sys

from .cli import main

sys.exit(main())
