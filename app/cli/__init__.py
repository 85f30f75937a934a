"""The ``inclinometer`` sub-commands, one module each (``app/cli/<command>.py``).

:func:`main` parses and dispatches (:mod:`app.cli.dispatch`); a command's module is imported
only when that command runs. Bad input ends in one line ``inclinometer: MESSAGE`` and exit
status 2 (:mod:`app.cli.errors`); ``--debug`` or ``INCLINOMETER_DEBUG=1`` shows Python's
tracebacks. The window itself starts from :mod:`app.launcher`: this package never imports
``app.gui`` (an import-linter contract).
"""

from app.cli.dispatch import build_parser, main

__all__ = ["build_parser", "main"]
