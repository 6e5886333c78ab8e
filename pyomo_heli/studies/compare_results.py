"""Compare a regenerated results folder with the committed one, number by number.

    python studies/regenerate_docs.py --run case1 --out /tmp/r --compare    # run, then compare with docs/results
    python studies/regenerate_docs.py --compare case1 --out /tmp/r          # compare a folder already run

Two numbers agree when ``|new - ref| <= max(RTOL * |ref|, ATOL)``; the difference printed is the relative one,
``|new - ref| / max(|ref|, ATOL / RTOL)`` (so values below ``ATOL / RTOL = 1e-3`` in size are held to the
absolute floor ``ATOL`` in the file's own units), and a folder agrees when every one of its numbers is within
``RTOL``. What is compared, per file of the committed folder (its kept files; figures are not compared):

- ``.json``: recursively, every number; texts, booleans and null must be equal; list lengths too; a key of the
  committed file must be there (a key it does not have yet, written by newer code, is listed, not compared);
- ``.csv``: cell by cell under the same header, numbers as numbers, other cells as text;
- ``.md``: its tables (lines starting with ``|``), each against the table of the same header (a table newer
  report code adds is listed, not compared); a printed number is rounded, so it may also
  differ by one unit of its last printed digit (``1.08`` vs ``1.09`` when the value sits on a rounding edge;
  only the part of a difference beyond that unit counts);
  the text around the numbers must be equal. Text outside tables (run times, paths) is not compared. The
  strict check is the JSON and CSV one: the tables show the same numbers rounded.

Fields that are timings or machine facts are skipped wherever they occur (a JSON key, a CSV column, a Markdown
column header with its unit dropped and spaces as ``_``): :data:`IGNORED`.
"""
from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

RTOL = 1e-6
ATOL = 1e-9
# timings, and facts of the machine, the checkout or the code version rather than results
IGNORED = frozenset((
    "wall_time", "setup_time", "cold_wall_time", "build_time", "solver_setup_time", "total_time",
    "uncertainty_time", "cpu_time", "time_s", "wall_time_s", "elapsed",  # timings [s]
    # the benchmark's timings, their ratios and breakdowns, and the targets judged on them (its iterations and
    # estimates are compared)
    "clock_time", "solve_time", "a_solve_time", "a_solve_times", "a_time_per_iteration", "a_time_ratio",
    "front_time_ratio", "scaled_a_time_ratio", "scaled_front_time_ratio", "interior_cold_time", "interior_warm_time",
    "warm_over_cold_time", "front_over_cold_a", "front_end_to_end_over_a_end_to_end", "setup_share_of_front",
    "setup_time_exponent", "solve_time_exponent", "time_per_iteration_exponent", "shooting_over_a_solve_only",
    "shooting_over_full_discretization", "nl_route_a_solve_over_point_rows_a_solve",
    "nl_route_setup_over_point_rows_setup", "cpu_ratio", "wall_ratio", "cpu_s", "wall_s", "setup_breakdown",
    "a_solve_breakdown", "targets", "load_average_start", "load_average_end", "machine", "date_utc", "cpus",
    "dataset", "config", "results_dir", "path", "paths", "command", "out",  # paths of this checkout, command lines
    "fingerprint", "model_fingerprint", "extension_forms", "config_sha256", "dataset_sha256", "source_sha256",
    "config_text",
    "versions", "version", "python", "platform", "host", "hostname", "date", "created", "started", "finished",
    "provenance",  # hashes and copies of the inputs and the code, versions, dates
))
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Comparison:
    """What a comparison of one folder found: counts, the worst relative difference and where, the mismatches."""

    files: int = 0
    numbers: int = 0
    worst: float = 0.0
    where: str = ""
    mismatches: list[str] = field(default_factory=list)
    added: list[str] = field(default_factory=list)  # JSON keys the committed file does not have yet
    roots: tuple[str, str] | None = None  # (committed root, regenerated root) as given: a path names its own root

    @property
    def ok(self) -> bool:
        return not self.mismatches

    def number(self, ref: float, new: float, where: str, slack: float = 0.0) -> None:
        """Count one pair; ``slack`` is an absolute allowance (one unit of a printed number's last digit)."""
        self.numbers += 1
        if math.isnan(ref) or math.isnan(new) or math.isinf(ref) or math.isinf(new):
            if not (ref == new or (math.isnan(ref) and math.isnan(new))):
                self.mismatches.append(f"{where}: {ref!r} -> {new!r}")
            return
        diff = max(abs(new - ref) - slack, 0.0)  # a printed number: what its rounding cannot explain
        rel = diff / max(abs(ref), ATOL / RTOL)
        if diff > max(RTOL * abs(ref), ATOL):
            self.mismatches.append(f"{where}: {ref!r} -> {new!r} (rel. {rel:.2e})")
        if rel > self.worst or not self.where:
            self.worst, self.where = rel, where

    def local(self, new):
        """``new`` with the regenerated root read as the committed one, where it is a path under it."""
        if self.roots and isinstance(new, str) and new.startswith(self.roots[1] + "/"):  # `--existing OUT/loop`
            return self.roots[0] + new[len(self.roots[1]):]
        return new

    def text(self, ref, new, where: str) -> None:
        new = self.local(new)
        if ref != new:
            self.mismatches.append(f"{where}: {ref!r} -> {new!r}")


def _as_float(x) -> float | None:
    if isinstance(x, bool) or x is None:
        return None
    if isinstance(x, (int, float)):
        return float(x)
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def compare_json(ref, new, where: str, c: Comparison) -> None:
    if isinstance(ref, dict) and isinstance(new, dict):
        for k in sorted(set(ref) | set(new)):
            if k in IGNORED:
                continue
            if k not in new:
                c.mismatches.append(f"{where}.{k}: missing")
            elif k not in ref:
                c.added.append(f"{where}.{k}")
            else:
                compare_json(ref[k], new[k], f"{where}.{k}", c)
    elif isinstance(ref, list) and isinstance(new, list):
        if len(ref) != len(new):
            c.mismatches.append(f"{where}: {len(ref)} items -> {len(new)}")
        for i, (r, n) in enumerate(zip(ref, new)):
            compare_json(r, n, f"{where}[{i}]", c)
    elif (not isinstance(ref, (bool, str)) and isinstance(ref, (int, float))
          and not isinstance(new, (bool, str)) and isinstance(new, (int, float))):
        c.number(float(ref), float(new), where, 0.0)
    else:
        c.text(ref, new, where)


def _ignored_header(h: str) -> bool:
    return re.sub(r"\s*\[.*?\]\s*$", "", h.strip()).replace(" ", "_").lower() in IGNORED


def compare_csv(ref: Path, new: Path, name: str, c: Comparison) -> None:
    with open(ref, newline="") as fr, open(new, newline="") as fn:
        r, n = list(csv.reader(fr)), list(csv.reader(fn))
    if not r or not n or r[0] != n[0]:
        c.mismatches.append(f"{name}: header {r[:1]} -> {n[:1]}")
        return
    header = r[0]
    if len(r) != len(n):
        c.mismatches.append(f"{name}: {len(r) - 1} rows -> {len(n) - 1}")
    for i, (rr, nn) in enumerate(zip(r[1:], n[1:]), start=1):
        for h, a, b in zip(header, rr, nn):
            if _ignored_header(h):
                continue
            fa, fb = _as_float(a), _as_float(b)
            if fa is not None and fb is not None:
                c.number(fa, fb, f"{name} row {i} {h}")
            else:
                c.text(a, b, f"{name} row {i} {h}")


def _last_digit_unit(token: str) -> float:
    """One unit of the last printed digit of a number as printed: 1.08 -> 0.01, 6.3e+04 -> 1e3, 24 -> 1."""
    mant, _, exp = token.lower().partition("e")
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 10.0 ** (int(exp or 0) - decimals)


def _md_tables(p: Path) -> list[tuple[tuple[str, ...], list[list[str]]]]:
    """The tables of a Markdown file: (header cells, rows of cells), in order."""
    out: list = []
    lines = [ln.strip() for ln in p.read_text().splitlines()]
    for i, ln in enumerate(lines):
        if not ln.startswith("|"):
            continue
        cells = [x.strip() for x in ln.strip("|").split("|")]
        if all(set(x) <= set("-: ") for x in cells):
            continue  # the |---| line under a header
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if nxt.startswith("|") and all(set(x.strip()) <= set("-: ") for x in nxt.strip("|").split("|")):
            out.append((tuple(cells), []))
        elif out:
            out[-1][1].append(cells)
    return out


def compare_printed(a: str, b: str, at: str, c: Comparison) -> None:
    """Two printed strings (a table cell, a line): the words must agree, each number to the tolerance or within
    one unit of its last printed digit."""
    b = c.local(b)  # before the numbers are read: a root may hold digits
    ta, tb = _NUMBER.findall(a), _NUMBER.findall(b)
    c.text(_NUMBER.sub("#", a), _NUMBER.sub("#", b), at)
    if len(ta) == len(tb):
        for x, y in zip(ta, tb):
            c.number(float(x), float(y), at, slack=max(_last_digit_unit(x), _last_digit_unit(y)))


def compare_md(ref: Path, new: Path, name: str, c: Comparison) -> None:
    """Each table of ``ref`` against the table of ``new`` with the same header (the n-th of that header);
    a table the committed file does not have (newer report code) is listed, not compared."""
    r, n = _md_tables(ref), _md_tables(new)
    pool: dict = {}
    for h, rows in n:
        pool.setdefault(h, []).append(rows)
    for h, rows in r:
        where = f"{name} table '{' | '.join(h)[:60]}'"
        if not pool.get(h):
            c.mismatches.append(f"{where}: missing")
            continue
        rows_n = pool[h].pop(0)
        if len(rows) != len(rows_n):
            c.mismatches.append(f"{where}: {len(rows)} rows -> {len(rows_n)}")
        for i, (rr, nn) in enumerate(zip(rows, rows_n), start=1):
            if len(rr) != len(nn):
                c.mismatches.append(f"{where} row {i}: {len(rr)} cells -> {len(nn)}")
                continue
            for col, a, b in zip(h, rr, nn):
                if _ignored_header(col):
                    continue
                compare_printed(a, b, f"{name} row {i} {col}", c)
    c.added += [f"{name} table '{' | '.join(h)[:60]}'" for h, left in pool.items() for _ in left]


def compare_text(ref: Path, new: Path, name: str, c: Comparison) -> None:
    """A printed output line by line: the words must agree, the numbers to the tolerance or their last digit."""
    r, n = ref.read_text().splitlines(), new.read_text().splitlines()
    if len(r) != len(n):
        c.mismatches.append(f"{name}: {len(r)} lines -> {len(n)}")
    for i, (a, b) in enumerate(zip(r, n), start=1):
        compare_printed(a, b, f"{name} line {i}", c)


def compare_folder(ref: Path, new: Path, keep: tuple[str, ...], text: tuple[str, ...] = (),
                   roots: tuple[str, str] | None = None) -> Comparison:
    """Compare every kept (committed) file of ``ref`` with the same file of ``new``: JSON, CSV and Markdown tables,
    and the printed outputs (``.txt``) that match a glob of ``text`` (those whose numbers hold no timings).
    ``roots``: the committed and the regenerated results root as the commands were given them; a string that is a
    path under the regenerated root is compared with that root replaced by the committed one."""
    from .regenerate import prune_matches

    c = Comparison(roots=roots)
    ref_files = sorted(p.relative_to(ref).as_posix() for p in ref.rglob("*") if p.is_file()
                       and prune_matches(p.relative_to(ref).as_posix(), keep))
    new_files = sorted(p.relative_to(new).as_posix() for p in new.rglob("*") if p.is_file()) if new.is_dir() else []
    for extra in sorted(set(new_files) - set(ref_files)):
        if prune_matches(extra, keep) and not extra.endswith(".png"):
            c.mismatches.append(f"{extra}: not in the committed folder")
    for rel in ref_files:
        suffix = Path(rel).suffix
        if suffix not in (".json", ".csv", ".md") and not (suffix == ".txt" and prune_matches(rel, text)):
            continue  # figures, printed outputs with timings (the benchmark's)
        if rel not in new_files:
            c.mismatches.append(f"{rel}: missing")
            continue
        c.files += 1
        if suffix == ".json":
            compare_json(json.loads((ref / rel).read_text()), json.loads((new / rel).read_text()), rel, c)
        elif suffix == ".csv":
            compare_csv(ref / rel, new / rel, rel, c)
        elif suffix == ".md":
            compare_md(ref / rel, new / rel, rel, c)
        else:
            compare_text(ref / rel, new / rel, rel, c)
    return c


def table(results: dict[str, Comparison], show: int = 10) -> str:
    """The per-entry table, then up to ``show`` mismatches of each folder that failed."""
    lines = [f"compared with rtol {RTOL:g} (absolute floor {ATOL:g}); ignored fields: {', '.join(sorted(IGNORED))}",
             "", "| entry | files | numbers | worst rel. diff | where | result |", "|---|---|---|---|---|---|"]
    for name, c in results.items():
        lines.append(f"| {name} | {c.files} | {c.numbers} | {c.worst:.2e} | {c.where if c.worst else '-'} | "
                     f"{'PASS' if c.ok else f'FAIL ({len(c.mismatches)})'} |")
    for name, c in results.items():
        if c.added:
            more = " ..." if len(c.added) > show else ""
            lines.append(f"\n{name}: {len(c.added)} fields or tables the committed files lack (written by code newer "
                         f"than them; not compared): {', '.join(c.added[:show])}{more}")
    for name, c in results.items():
        if not c.ok:
            lines.append(f"\n{name}: {len(c.mismatches)} mismatches" + (f", the first {show}:" if len(c.mismatches)
                                                                         > show else ":"))
            lines += ["  " + m for m in c.mismatches[:show]]
    return "\n".join(lines)
