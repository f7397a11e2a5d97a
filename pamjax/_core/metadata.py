"""pamjax's version, read from the installed package's metadata (`pyproject.toml` is its one source)."""

import importlib.metadata


def version() -> str:
    """The installed pamjax version; "0+unknown" for a source checkout that was never installed."""
    try:
        return importlib.metadata.version("pamjax")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"
