"""The gallery's scripts, one per figure, table or experiment of paper 000 (`p000_*`) and paper 001 (`p001_*`); the
module docstring of each says what it computes and from what data. Run them all with `pamjax reproduce`, some with
`pamjax reproduce --only NAME ...`, one on its own with `python -m pamjax.gallery.scripts.NAME [--quick]`."""
