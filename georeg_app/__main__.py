"""``python -m georeg_app``: the ``georeg`` command line."""
import sys

from georeg_app.cli import main

sys.exit(main())
