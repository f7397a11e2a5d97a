"""Output paths: nothing pamjax writes replaces a user's file unless asked to."""

import pathlib


def writable_path(path, overwrite):
    """`path` as a `pathlib.Path` with its folder made, ready to be written; a `FileExistsError` if it exists and
    `overwrite` is False."""
    path = pathlib.Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
