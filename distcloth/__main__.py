"""``python -m distcloth``: the same as the ``distcloth`` command."""
import sys

from .cli import main

sys.exit(main())
