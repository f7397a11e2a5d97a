"""Every number of paper 000, paper 001 and the data sheets that pamjax uses, each with its source; imports nothing.

- `paper000`: the MAS-10 + MHE2 plant (Table 1, set-up, PI gains).
- `paper001`: the VPPM regulator and the DMSP-40 set-up (eq. 5-8 constants, Tables 1-2, load).
- `datasheets`: Festo data sheets and the model numbers derived from them and the DMSP-20-300 force map (the
  derivations: `pamjax.presets`), assumed numbers marked as such.

Components take their defaults from here (`OnOffValve.supply_pressure` is `paper000.SUPPLY_PRESSURE`), and
`pamjax.presets` builds the papers' plants from them, so each number is written once.
"""
