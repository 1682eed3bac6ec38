"""``python -m workflow`` runs the ``tactile`` command line."""

import sys

from .cli import main

sys.exit(main())
