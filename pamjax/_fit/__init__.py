"""Fitting: recordings, experiments, parameter spaces, Levenberg-Marquardt, `fit`, diagnostics, bench loaders,
fingerprints, multistart and model files."""
