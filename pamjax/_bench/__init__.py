"""Bench folders: a `meta.json` and one recording per experiment, read and checked (`files`), and turned into the
experiments, free parameters and rig of a fit (`load`). Public as `pamjax.bench`."""
