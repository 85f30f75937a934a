"""Package data (stylesheets, icons) loaded through :mod:`importlib.resources`."""
