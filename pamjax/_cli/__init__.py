"""The `pamjax` command line: demo, fit, simulate, sweep, reproduce."""
