"""``python -m workflow`` runs the ``tactile`` command line."""

import sys

from workflow.cli import main

sys.exit(main())
