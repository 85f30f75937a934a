"""``python -m app`` runs the inclinometer command."""

import sys

from app.cli import main

sys.exit(main())
