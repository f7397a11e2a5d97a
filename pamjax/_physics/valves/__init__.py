"""Valves: the elements a command drives (contract in `base`), paper 000's on/off valve and its averaged model."""
