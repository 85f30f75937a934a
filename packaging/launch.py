"""Entry script for the frozen bundle (PyInstaller needs a file, not an entry point)."""

import sys

from app.frozen import prepare_frozen_environment

prepare_frozen_environment()

from app.launcher import main  # noqa: E402

sys.exit(main())
