"""Fitting: recordings, experiments (dynamic ones and the static bench tests), a rig's nuisances, parameter spaces,
predictions, the fit's compiled problem, its optimistix solver and how it is driven, `fit`, diagnostics, staged starts
and multistart. Model files and checkpoints are below (`pamjax._files`); bench folders (`pamjax._bench`), experiment
design and profile likelihoods (`pamjax._identifiability`) above."""
