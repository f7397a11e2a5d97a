"""Confidence bands on predictions: a fit's covariance carried to any prediction of the fitted model (trajectories,
steady-state maps, flow surfaces, frequency responses). A layer above the workflows: it reads fit results and runs
sweeps, which the fit and sweep layers may not do for each other."""
