"""``python -m app`` runs the inclinometer command."""

import sys

from app.launcher import main

sys.exit(main())
