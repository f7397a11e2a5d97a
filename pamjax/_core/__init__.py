"""Basic utilities every layer may use: errors, units, CSV files, the XLA CPU setting, the compilation cache,
multi-process runs, and the one place that reads private internals of dependencies."""
