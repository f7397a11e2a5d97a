"""Control: sampled-data controllers and closed loops, PID, antagonistic joint control runs."""
