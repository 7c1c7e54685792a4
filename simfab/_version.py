"""simfab's version (a module of its own, so library modules can read it without importing the package root)."""

__version__ = "0.1.0"
