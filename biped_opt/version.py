"""The package's version and where its sources lie (for cache keys and file headers)."""

from pathlib import Path

__all__ = ["__version__", "PACKAGE_DIR"]

__version__ = "0.1.0"
#: the directory of the biped_opt package
PACKAGE_DIR = Path(__file__).resolve().parent
