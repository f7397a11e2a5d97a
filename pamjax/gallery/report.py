"""The gallery's pages, written from the catalogue and a run's numbers: the index of a `pamjax reproduce` run
(`index_page`) and the tables of `docs/papers.md` (`paper_tables`, used by `pamjax.gallery.docs`).

A run is a dict (`run.json` in the output folder): `format`, `state` ("complete", "interrupted" or "running"),
`quick`, `started`, `finished`, `pamjax_version`, `machine`, `scripts` (script name → its record: `paper`, `title`,
`seconds`, `finished`, `numbers`, ...). Every status and reading comes from `catalogue.verdict` on those numbers.
"""

import collections

from . import catalogue

TITLES = {"000": "Paper 000: MAS-10-300 lifting 9.6 kg through an MHE2 on/off valve at 50 Hz PWM",
          "001": "Paper 001: VPPM proportional pressure regulator feeding a DMSP-40-400 with 893 N"}
FORMAT = "pamjax-reproduce-run"


def cell(text):
    return str(text).replace("|", "\\|").replace("\n", " ")


def verdicts(run):
    """Every entry's verdict for `run` (a script left out of the run: "not run")."""
    return catalogue.verdicts_of(run.get("scripts", {}))


def counts(vs):
    """status → number of entries, in the order of `catalogue.STATUSES` (then the others)."""
    c = collections.Counter(v.status for v in vs)
    order = [*catalogue.STATUSES, catalogue.NOT_RUN, catalogue.MISSING_NUMBER]
    return {s: c[s] for s in order if c[s]}


def paper_tables(vs, figures_under=None, heading="##"):
    """Markdown: per paper, one table item | what | paper | pamjax | status | reading (| figure when
    `figures_under` gives the folder the figures are in, relative to the page: "" for the run's folder)."""
    lines, ran = [], {v.entry.script for v in vs if v.status != catalogue.NOT_RUN}
    for paper in catalogue.ITEMS:
        mine = [v for v in vs if v.entry.paper == paper]
        c = counts(mine)
        lines += [f"{heading} {TITLES[paper]}", "",
                  f"{len(catalogue.ITEMS[paper])} items, {len(mine)} entries: "
                  + ", ".join(f"{n} {s}" for s, n in c.items()) + ".", ""]
        head = "| item | what | paper | pamjax | status | reading |"
        rule = "|---|---|---|---|---|---|"
        if figures_under is not None:
            head, rule = head + " figure |", rule + "---|"
        lines += [head, rule]
        for v in mine:
            e = v.entry
            row = [e.item, e.what, e.paper_says or "—", v.pamjax or "—", f"**{v.status}**", v.reading]
            line = "| " + " | ".join(cell(x) for x in row) + " |"
            if figures_under is not None:
                fig = f"[{e.figure}]({figures_under}{e.script}/{e.figure})" if e.figure and e.script in ran else ""
                line += f" {fig} |"
            lines.append(line)
        lines.append("")
    return lines


def index_page(run):
    """The Markdown index of a run: what ran and how, each paper's table, the scripts' seconds."""
    vs = verdicts(run)
    scripts = run.get("scripts", {})
    total = sum(r.get("seconds", 0.0) for r in scripts.values())
    state = run.get("state", "complete")
    lines = ["# pamjax against papers 000 and 001: the gallery", ""]
    if state != "complete":
        lines += [f"**{state.upper()}**: {len(scripts)} of the run's {len(run.get('planned', scripts))} scripts "
                  "finished; the others have no numbers here (status \"not run\").", ""]
    mode = "--quick" if run.get("quick") else "full mode"
    lines += [
        f"`pamjax reproduce` ({mode}), pamjax {run.get('pamjax_version', '?')}, started {run.get('started', '?')}, "
        f"{'finished ' + run['finished'] if run.get('finished') else 'not finished'} on {run.get('machine', '?')}: "
        f"{len(scripts)} scripts, {total:.0f} s in the scripts. Statuses are computed from the numbers "
        "(`pamjax.gallery.catalogue`): reproduced / differs (pamjax's number against the paper's, with the stated "
        "tolerance), procedure check (truth in, truth out; never a reproduction), not implemented, no numbers. Each "
        "script's figures and `<script>.json` (its numbers) are in its folder; `run.json` holds them all.", ""]
    lines += paper_tables(vs, figures_under="")
    lines += ["## Scripts", "", "| script | paper | title | mode | finished | seconds |", "|---|---|---|---|---|---|"]
    for name, r in sorted(scripts.items()):
        lines.append(f"| `{name}` | {r['paper']} | {cell(r['title'])} | {'quick' if r.get('quick') else 'full'} | "
                     f"{r.get('finished', '?')} | {r.get('seconds', 0.0):.1f} |")
    lines.append("")
    return "\n".join(lines)
