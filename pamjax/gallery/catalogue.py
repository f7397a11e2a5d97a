"""Every item of papers 000 and 001 (each equation, table, figure and quantitative sentence), with its status computed
from the numbers: the one source of the gallery's index (`pamjax reproduce`) and of `docs/papers.md`.

An item (`ITEMS`, the paper's own label: "eq. 11", "Table 1", "Fig. 7", "text: ...") has one or more entries
(`Entry`, in `items000.py` and `items001.py`). An entry is of one of four kinds, and its status follows from its kind
and, for the first two, from the numbers a gallery script computed:

- `COMPARE`: pamjax's number(s) against the paper's. Each `Check` names a number of the script's `Result.numbers` (by
  path) and a `Target`: the paper's value with a stated tolerance (`Near`), a range the paper prints (`Between`), or a
  bound that a qualitative sentence is read as (`AtLeast`, `AtMost`; the reading is the target's `why`). Status
  **reproduced** if every check holds, else **differs** (with both numbers, the difference and the entry's `reason`).
- `PROCEDURE`: a procedure check: the truth is put in (the paper's value as the truth of synthetic data, the same
  equations solved by independent code, an identity of pamjax's own model, an implementation against a transcription
  of the printed equation) and the check says whether it came out. Status **procedure check** whatever the numbers;
  the reading says "truth recovered" or "truth NOT recovered". Never presented as a reproduction.
- `NOT_IMPLEMENTED`: status **not implemented**; `reason` names what is missing.
- `NO_NUMBERS`: status **no numbers**: the paper shows hardware, a block diagram or a proposal without a number or a
  checkable claim; `reason` says what pamjax has instead (numbers shown, if any, are for information).

Readings are written here from the numbers and the targets (`verdict`); nothing is pinned. A comparison of a model
with itself is a `PROCEDURE`, never a `COMPARE`.

**Adding an item or a script** (e.g. a new `pamjax/gallery/scripts/p000_14_creep.py`):

1. The script computes its numbers into `Result.numbers` and lists the items in `COVERS`.
2. In `items000.py` (or `items001.py`), replace the item's `NOT_IMPLEMENTED` entry (or add one) with a `COMPARE` or
   `PROCEDURE` entry: `Entry("000", "text: creep ...", "what is compared", COMPARE, "p000_14_creep",
   paper_says="...", checks=(Check("creep at x_max", "creep/mm", Near(1.0, rel=0.2, why="...")),),
   reason="why it differs, when known")`. A new item also goes into `ITEMS` below.
3. `python -m pamjax.gallery.docs --run` regenerates `docs/papers.md` (and `docs/papers.json`, its numbers);
   `tests/test_gallery.py` fails until every item has an entry, every script's `COVERS` is matched by entries, and the
   docs are current.
"""

import dataclasses
import math

COMPARE, PROCEDURE, NOT_IMPLEMENTED, NO_NUMBERS = "compare", "procedure", "not implemented", "no numbers"
KINDS = (COMPARE, PROCEDURE, NOT_IMPLEMENTED, NO_NUMBERS)
REPRODUCED, DIFFERS, PROCEDURE_CHECK = "reproduced", "differs", "procedure check"
STATUSES = (REPRODUCED, DIFFERS, PROCEDURE_CHECK, NOT_IMPLEMENTED, NO_NUMBERS)
NOT_RUN, MISSING_NUMBER = "not run", "number missing"  # in an index whose run left the script out; a broken script


def _items(prefix, numbers):
    return [f"{prefix} {n}" for n in numbers]


# Every item of both papers: equations, tables, figures, and the sentences that state a number or a checkable result.
ITEMS = {
    "000": [
        *_items("eq.", range(1, 22)), "Table 1", *_items("Fig.", range(1, 17)),
        "text: maximum contraction without load 20-25 %",
        "text: switching time 2 ms, usable duty 10-90 %",
        "text: exhaust silencer explains Fig. 12's offset",
        "text: pressure ripple ≈ 15 kPa",
        "text: 25 Hz PWM chatters, 100 Hz is smoother",
        "text: 100 Hz PWM gives a poor duty resolution at 0.1 ms sampling",
        "text: creep near the maximum displacement",
        "text: largest errors on the way down (no transition between loop branches)",
        "text: derivative term works in simulation, fails with measurement noise",
        "text: sliding mode control with the SVSF state estimator",
    ],
    "001": [
        *_items("eq.", range(1, 15)), "Table 1", "Table 2", *_items("Fig.", range(1, 15)),
        "text: VPPM accuracy 2 %",
        "text: VPPM pressure hysteresis 50 mbar",
        "text: VPPM operating modes fast / universal / precise",
        "text: output pressure held for up to 100 times the flow",
        "text: DMSP-40-400, 6000 N, 25 % contraction",
        "text: G_Vref identified with 94.64 % fit (60/40 split, Butterworth 20 Hz)",
        "text: eq. 7 reduces to second order",
        "text: eq. 8's denominator is second order with real poles",
        "text: with the muscle attached the valve is slower than eq. 6",
        "text: peak valve inflow 2.79 / 4.34 l/min at 3 / 5 V",
        "text: discharging C and b do not depend on the pressure",
        "text: future work, antagonistic pair on an ankle joint",
        "text: future work, activation and contraction dynamics",
        "text: future work, C and b against the diaphragm aperture",
    ],
}


def _paper_spec(spec):
    """The format of a paper's value beside pamjax's `spec`: as given when a percentage or exponent, else 4 figures
    (the paper's numbers keep their digits)."""
    return spec if spec.endswith(("%", "e")) else ".4g"


def _fmt(x, spec=".4g"):
    return format(x, spec) if isinstance(x, (int, float)) and not isinstance(x, bool) else str(x)


@dataclasses.dataclass(frozen=True)
class Near:
    """The paper's `value`, within `abs` or `rel` (a fraction); `why`: the reason for that tolerance."""

    value: float
    abs: float | None = None
    rel: float | None = None
    why: str = ""

    def tolerance(self):
        return self.abs if self.abs is not None else self.rel * abs(self.value)

    def holds(self, v):
        return abs(v - self.value) <= self.tolerance()

    def describe(self, spec=".4g"):
        spec = _paper_spec(spec)
        tol = f"± {_fmt(self.abs, spec)}" if self.abs is not None else f"± {100 * self.rel:g} %"
        return f"{_fmt(self.value, spec)} {tol}"

    def difference(self, v, spec=".4g"):
        d = v - self.value
        rel = f", {100 * d / self.value:+.1f} %" if self.value else ""
        return f"{'+' if d >= 0 else ''}{_fmt(d, '.2g')}{rel}"


@dataclasses.dataclass(frozen=True)
class Between:
    """A range [`lo`, `hi`] (the paper prints a range, or a claim is read as one); `why`: the reading."""

    lo: float
    hi: float
    why: str = ""

    def holds(self, v):
        return self.lo <= v <= self.hi

    def describe(self, spec=".4g"):
        spec = _paper_spec(spec)
        return f"{_fmt(self.lo, spec)} to {_fmt(self.hi, spec)}"

    def difference(self, v, spec=".4g"):
        if self.holds(v):
            return ""
        edge = self.lo if v < self.lo else self.hi
        return f"{_fmt(v - edge, '+.2g')} beyond {_fmt(edge, spec)}"


@dataclasses.dataclass(frozen=True)
class AtLeast:
    """v ≥ `bound` (a claim read as a bound, `why`)."""

    bound: float
    why: str = ""

    def holds(self, v):
        return v >= self.bound

    def describe(self, spec=".4g"):
        return f"≥ {_fmt(self.bound, _paper_spec(spec))}"

    def difference(self, v, spec=".4g"):
        return "" if self.holds(v) else f"{_fmt(v - self.bound, '+.2g')} short"


@dataclasses.dataclass(frozen=True)
class AtMost:
    """v ≤ `bound` (a claim read as a bound, `why`)."""

    bound: float
    why: str = ""

    def holds(self, v):
        return v <= self.bound

    def describe(self, spec=".4g"):
        return f"≤ {_fmt(self.bound, _paper_spec(spec))}"

    def difference(self, v, spec=".4g"):
        return "" if self.holds(v) else f"{_fmt(v - self.bound, '+.2g')} over"


@dataclasses.dataclass(frozen=True)
class Check:
    """One number of an entry: `label`, its `path` in the script's numbers ("a/b/0", or a tuple of keys for keys
    that contain a slash), the `target` it is checked against (None: shown only), its `unit` and format `spec`."""

    label: str
    path: str | tuple
    target: Near | Between | AtLeast | AtMost | None = None
    unit: str = ""
    spec: str = ".4g"


@dataclasses.dataclass(frozen=True)
class Entry:
    """One line of the catalogue (see the module docstring): `paper`, `item` (a label of `ITEMS`), `what` is
    compared, `kind`, the `script` that computes its numbers, `paper_says` (the paper's number or claim as printed),
    `checks`, `basis` (what pamjax's number is computed from, or the truth a procedure check puts in), `reason` (why
    it differs, what is missing, or what pamjax has instead), `figure` (file in the script's folder)."""

    paper: str
    item: str
    what: str
    kind: str
    script: str = ""
    paper_says: str = ""
    checks: tuple = ()
    basis: str = ""
    reason: str = ""
    figure: str = ""


@dataclasses.dataclass
class Verdict:
    """An entry's status with the numbers it rests on: `status` (one of `STATUSES`, or `NOT_RUN` /
    `MISSING_NUMBER`), `pamjax` (pamjax's numbers, formatted), `reading` (written from the numbers), `values`
    (label → number) and `holds` (label → whether its target holds)."""

    entry: Entry
    status: str
    pamjax: str
    reading: str
    values: dict
    holds: dict


def lookup(numbers, path):
    """`numbers[a][b]…` for the path "a/b/…" (list indices as integers), or for a tuple of keys."""
    for key in (path.split("/") if isinstance(path, str) else path):
        numbers = numbers[int(key)] if isinstance(numbers, list) else numbers[key]
    return numbers


def _number(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"not a finite number: {value!r}")
    return float(value)


def verdict(entry, numbers):
    """The `Verdict` of `entry` given its script's `numbers` (None: the script was not run)."""
    if entry.kind == NOT_IMPLEMENTED:
        return Verdict(entry, NOT_IMPLEMENTED, "—", f"Not implemented: {entry.reason}", {}, {})
    if numbers is None:
        if entry.kind in (COMPARE, PROCEDURE):
            return Verdict(entry, NOT_RUN, "", f"{entry.script} was not run", {}, {})
        return Verdict(entry, NO_NUMBERS, "—", entry.reason, {}, {})
    values, holds, parts = {}, {}, []
    for c in entry.checks:
        try:
            values[c.label] = _number(lookup(numbers, c.path))
        except (KeyError, IndexError, TypeError, ValueError) as err:
            return Verdict(entry, MISSING_NUMBER, "", f"number {c.path!r} of {entry.script}: {err!r}", values, holds)
        if c.target is not None:
            holds[c.label] = c.target.holds(values[c.label])
    shown = "; ".join(f"{c.label} {_fmt(values[c.label], c.spec)}{' ' + c.unit if c.unit else ''}"
                      for c in entry.checks)
    for c in entry.checks:
        if c.target is None:
            continue
        v, t = values[c.label], c.target
        why = f" ({t.why})" if t.why else ""
        diff = t.difference(v, c.spec)
        parts.append(f"{c.label} {_fmt(v, c.spec)} vs {t.describe(c.spec)}{why}: "
                     f"{'holds' if holds[c.label] else 'does not hold'}{f' ({diff})' if diff else ''}")
    checked = "; ".join(parts)
    every = all(holds.values())
    if entry.kind == COMPARE:
        status = REPRODUCED if every else DIFFERS
        reading = f"{checked}. pamjax's numbers: {entry.basis}." if entry.basis else f"{checked}."
        if status == DIFFERS:
            reading += f" Why: {entry.reason}" if entry.reason else " The reason is not known."
        return Verdict(entry, status, shown, reading, values, holds)
    if entry.kind == PROCEDURE:
        head = "Procedure check, truth recovered" if every else "Procedure check, truth NOT recovered"
        if not holds:
            head = "Procedure check (numbers shown, no pass criterion)"
        reading = f"{head}: {checked}." if checked else f"{head}."
        reading += f" Truth in: {entry.basis}." if entry.basis else ""
        return Verdict(entry, PROCEDURE_CHECK, shown, reading, values, holds)
    return Verdict(entry, NO_NUMBERS, shown or "—", entry.reason, values, holds)


def entries():
    """Every entry of both papers, in the papers' order."""
    from . import items000, items001

    return [*items000.ENTRIES, *items001.ENTRIES]


def verdicts_of(records, scripts=None):
    """Verdicts of every entry (or of those of `scripts`) from the run's `records` (script → record with
    `numbers`; a script without a record counts as not run)."""
    out = []
    for e in entries():
        if scripts is not None and e.script not in scripts:
            continue
        record = records.get(e.script) if e.script else None
        out.append(verdict(e, None if record is None else record["numbers"]))
    return out


def coverage_problems(script_covers=None):
    """What is wrong with the catalogue itself (empty when nothing): an item of `ITEMS` without an entry, an entry
    whose item is not in `ITEMS`, an unknown kind, a `COMPARE` entry without a target, a `PROCEDURE` or `COMPARE`
    entry without a script, a `NOT_IMPLEMENTED` entry that names nothing; with `script_covers` (script → its
    `COVERS`), an item a script covers that has no entry computed by that script."""
    problems = []
    all_entries = entries()
    for paper, items in ITEMS.items():
        have = {e.item for e in all_entries if e.paper == paper}
        problems += [f"paper {paper}: {i!r} has no entry" for i in items if i not in have]
        problems += [f"paper {paper}: entry for {i!r}, which is not in ITEMS" for i in sorted(have - set(items))]
    for e in all_entries:
        where = f"paper {e.paper} {e.item!r} ({e.what})"
        if e.kind not in KINDS:
            problems.append(f"{where}: unknown kind {e.kind!r}")
        if e.kind in (COMPARE, PROCEDURE) and not (e.script and e.checks):
            problems.append(f"{where}: a {e.kind} entry needs a script and checks")
        if e.kind == COMPARE and not any(c.target is not None for c in e.checks):
            problems.append(f"{where}: a comparison without a target compares nothing")
        if e.kind in (NOT_IMPLEMENTED, NO_NUMBERS) and not e.reason:
            problems.append(f"{where}: say what is missing or what pamjax has instead (reason)")
    for script, covers in (script_covers or {}).items():
        computed = {e.item for e in all_entries if e.script == script}
        problems += [f"{script} covers {i!r} but no catalogue entry is computed by it" for i in covers
                     if i not in computed]
        problems += [f"{script} computes the entry of {i!r} but does not list it in COVERS" for i in sorted(computed)
                     if i not in covers]
    return problems
