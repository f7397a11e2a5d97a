"""Solvers: `simulate`, the fixed grids (PWM-synchronous and uniform, with events), Rodas5, the batched
fixed-step schemes, the discrete-time model, linearisation, solve hints and gradient checks."""
