"""``python -m evstwin`` runs the evstwin command."""

import sys

from .cli import main

sys.exit(main())
