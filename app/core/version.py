"""The application's version, in the core so that every layer can name it without looking up."""

__version__ = "0.1.0"
