"""The procedures of `fits/` that the paper gallery reuses, as modules of the package (so that `pamjax reproduce`
runs from an installed wheel): the `fits/` scripts import them from here and add their command lines.

- `force_map`: the DMSP-20-300 force map (`pamjax/data/`), eq. 7's start model, the preset derivation's steps
  (`fits/static_force.py`, `fits/derive_presets.py`);
- `averaged_valve`: eq. 13 by two routes, scored on the cycle-averaged flow (`fits/averaged_valve.py`);
- `bench`: the hybrid bench's plant and tank from its `meta.json` (`fits/control.py`, `fits/valve_tank.py`);
- `linearised`: a linearised regulator described in the paper's units (`fits/linearise.py`);
- `regulator`: paper 001's C, b from tank runs and G_Vref from a square wave (`fits/regulator.py`);
- `stiffness`: paper 001's eq. 9-11 along a 1.5 Hz run (`fits/stiffness.py`);
- `ankle`: the antagonistic ankle pair, feed-forward along a gait angle (`fits/ankle.py`).
"""
