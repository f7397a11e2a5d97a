"""CSV tables with units in the header (`t [s],pressure [Pa abs],position [mm]`): the reader behind
`Recording.from_csv` and the writer of every CSV pamjax produces (`Recording.to_csv`, `pamjax simulate`, `pamjax
sweep`, `pamjax demo`).

The reader takes what spreadsheets and bench software write: the standard library's `csv` parser with the
delimiter sniffed (comma, semicolon, tab or bar), quoted headers, a UTF-8 byte-order mark (Excel's "CSV UTF-8"),
Windows-1252 text, UTF-16 (Excel's "Unicode Text"), Excel's `sep=;` first line, decimal commas in semicolon- or
tab-separated files, `#` comment lines, units as `name [unit]` or `name (unit)`. What it cannot read unambiguously it
refuses by name: a non-numeric cell (file, line, column), a ragged row, two columns of one name, a row-index column
(pandas' `to_csv` writes one unless `index=False`).
"""

import csv
import pathlib
import re

import numpy as np

from .errors import PamjaxInputError

_DELIMITERS = (",", ";", "\t", "|")
_MISSING = {"", "nan", "na", "n/a", "null", "none", "-nan"}  # lower-case; NaN cells (refused unless mask_nan)
_INDEX_NAMES = {"", "index", "idx", "row", "rownames"}  # lower-case names of a row-index column
# `name [unit]` or `name (unit)`; the round form may nest one level of brackets, as the gauge suffix does:
# `pressure (bar(g))`, `pressure (MPa (abs.))` (docs/cli.md, Units)
_UNIT = re.compile(r"^(.*?)\s*(?:\[([^\]]*)\]|\(((?:[^()]|\([^()]*\))*)\))\s*$")
_SAMPLE_LINES = 50  # lines the delimiter is sniffed from


def _decode(path):
    data = pathlib.Path(path).read_bytes()
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):  # UTF-16 with its BOM: Excel's "Unicode Text", LabVIEW, PowerShell
        return data.decode("utf-16")  # (was: read byte by byte as cp1252, every other character a NUL)
    if len(data) >= 4 and data.count(0) >= len(data) // 4:  # UTF-16 without a BOM: ASCII with a NUL beside each byte
        return data.decode("utf-16-le" if data[1] == 0 else "utf-16-be", errors="replace")
    for encoding in ("utf-8-sig", "cp1252"):  # a BOM is dropped; Excel on Windows writes cp1252
        try:
            return data.decode(encoding)
        except UnicodeDecodeError:
            continue
    return data.decode("latin-1")  # every byte decodes; the cells that matter are numbers


def _split(line, delimiter):
    return [cell.strip() for cell in next(csv.reader([line], delimiter=delimiter, skipinitialspace=True))]


def sniff_delimiter(lines):
    """The delimiter that splits the header into the most columns with every sampled data line the same width."""
    best, best_width = ",", 0
    for d in _DELIMITERS:
        widths = [len(_split(line, d)) for _, line in lines[:_SAMPLE_LINES]]
        if widths[0] >= 2 and widths[0] > best_width and all(w == widths[0] for w in widths):
            best, best_width = d, widths[0]
    if best_width == 0:  # ragged with every delimiter: the one that splits the header most, so the error is useful
        best = max(_DELIMITERS, key=lambda d: len(_split(lines[0][1], d)))
    return best


def split_header(cell):
    """`'pressure [bar abs]'` → ('pressure', 'bar abs'); `'force (N)'` → ('force', 'N'); `'p (bar(g))'` → ('p',
    'bar(g)'); `'x'` → ('x', None)."""
    m = _UNIT.match(cell)
    if m is None:
        return cell.strip(), None
    unit = m.group(2) if m.group(2) is not None else m.group(3)
    return m.group(1).strip(), unit.strip()


def _number(cell, decimal_comma):
    if cell.lower() in _MISSING:
        return np.nan
    try:
        return float(cell)
    except ValueError:
        if decimal_comma and cell.count(",") == 1 and "." not in cell:
            return float(cell.replace(",", "."))  # raises ValueError again if it is still not a number
        raise


def read_table(path, keep=None):
    """Read a CSV table: list of (name, unit or None, float array), in column order. `keep` (a callable name → bool;
    None: every column) chooses the columns to read: another column is left unread whatever its cells hold (text,
    empty cells) and returned as (name, unit, None); names are checked (index column, doubles) among those read."""
    path = pathlib.Path(path)
    if not path.exists():
        raise PamjaxInputError(f"recording file {path} does not exist")
    if path.is_dir():
        raise PamjaxInputError(f"recording file {path} is a folder, not a CSV file")
    lines = [(k + 1, line) for k, line in enumerate(_decode(path).splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise PamjaxInputError(f"{path}: no header line (the file is empty or only comments)")
    directive = re.fullmatch(r"\s*sep=(.)\s*", lines[0][1], flags=re.IGNORECASE)
    if directive:  # Excel's `sep=;` first line names the delimiter (was: read as a one-column header)
        lines = lines[1:]
        if not lines:
            raise PamjaxInputError(f"{path}: no header line after the 'sep=' line")
    delimiter = directive.group(1) if directive else sniff_delimiter(lines)
    header_line, header_text = lines[0]
    header = _split(header_text, delimiter)
    if len(header) < 2:
        raise PamjaxInputError(
            f"{path}, line {header_line}: the header {header_text.strip()!r} has one column; a recording needs a "
            "time column 't' and at least one channel, separated by commas, semicolons or tabs"
        )
    names, units = zip(*(split_header(h) for h in header))
    read = [keep is None or bool(keep(n)) for n in names]
    rows = []
    for lineno, line in lines[1:]:
        cells = _split(line, delimiter)
        if len(cells) == len(header) + 1 and cells[-1] == "":
            cells = cells[:-1]  # a trailing delimiter
        if len(cells) != len(header):
            raise PamjaxInputError(f"{path}, line {lineno} (data row {len(rows)}): {len(cells)} columns, the header "
                                   f"has {len(header)}")
        row = []
        for j, cell in enumerate(cells):
            if not read[j]:
                row.append(np.nan)  # a column not asked for: its cells are not read
                continue
            try:
                row.append(_number(cell, decimal_comma=delimiter != ","))
            except ValueError:
                raise PamjaxInputError(
                    f"{path}, line {lineno} (data row {len(rows)}), column {j + 1} ({header[j]!r}): {cell!r} is not a "
                    "number"
                ) from None
        rows.append(row)
    data = np.asarray(rows, dtype=float).reshape(-1, len(header))
    columns = [(j, n, u, data[:, j] if read[j] else None) for j, (n, u) in enumerate(zip(names, units))
               if n or u is not None or (read[j] and not np.all(np.isnan(data[:, j])))]  # not an empty unnamed one
    _check_names(path, [(j, n, header[j]) for j, n, _, v in columns if v is not None])
    return [(n, u, v) for _, n, u, v in columns]


def _check_names(path, named):
    """`named`: (0-based column, name, header cell) of the columns read."""
    seen = {}
    for j, name, cell in named:
        if name.lower() in _INDEX_NAMES or name.lower().startswith("unnamed:"):
            raise PamjaxInputError(
                f"{path}: column {j + 1} ({cell!r}) looks like a row index, not a channel (pandas' DataFrame.to_csv "
                "writes one unless index=False): remove it, or write the file with index=False"
            )
        if name in seen:
            raise PamjaxInputError(
                f"{path}: columns {seen[name] + 1} and {j + 1} are both named {name!r}; rename one (a second column "
                "of one name would silently replace the first)"
            )
        seen[name] = j


def write_table(path, columns, units, comment=None):
    """Write `columns` (name → 1-D array, in order) as CSV with a `name [unit]` header; floats exact (repr)."""
    names = list(columns)
    with open(path, "w", newline="", encoding="utf-8") as f:
        if comment:
            f.write("".join(f"# {line}\n" for line in comment.splitlines()))
        writer = csv.writer(f)
        writer.writerow([f"{n} [{units[n]}]" if units.get(n) is not None else n for n in names])
        for row in zip(*(np.ravel(np.asarray(columns[n])) for n in names)):
            writer.writerow([repr(float(v)) for v in row])
    return path

