"""What data can tell about a model's parameters, above the fit: experiment design (`design`: a PWM duty signal that
maximises the information of a recording) and profile likelihoods (`profile`: likelihood-ratio intervals and
identifiability verdicts of a fit). Both reach the fit through its public contracts only: its parameter space, its
compiled residuals and Jacobian (`pamjax._fit.problem`), its solver (`pamjax._fit.drive`) and its experiments."""
