"""Systems: components composed into one ODE vector field over a named state (tank, muscle, regulated muscle,
antagonistic joint, the joint's closed loop)."""
