"""Serial arms from their DH table (CSV): an MJCF model and its error model, one command.

    pkm-calib from-dh TABLE.csv --name NAME --out-dir DIR [--targets target_1,...]
        [--no-target-errors] [--no-base-errors]

writes ``DIR/NAME.xml`` and ``DIR/NAME.params.toml`` (together; existing ones only with
``--force``). ``twin.formats.dh_mjcf`` says how the model is built and which parameter is
which. The error model holds the base's placement in the world (``base.*``) unless ``--no-base-
errors``.

Table format (UTF-8 CSV; blank lines and lines starting with ``#`` are skipped)::

    # convention: modified
    joint,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg[,type,home_deg,min_mm,max_mm,home_mm]
    A1,0,0,400,0,-170,170
    ...
    site,x_mm,y_mm,z_mm[,rx_deg,ry_deg,rz_deg]
    tool,0,0,120
    target_1,40,0,110

* ``# convention: standard|modified`` is mandatory, before the joint header. ``standard``
  (Denavit-Hartenberg): T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i); ``modified`` (Craig):
  T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i), row i printing alpha_{i-1}, a_{i-1},
  d_i, theta_i as vendors do. The base frame is frame 0, the last row's frame n the flange.
* One row per joint, in chain order. ``type`` is ``R`` (revolute, the default) or ``P``
  (prismatic). The joint value q is the commanded (encoder) value: theta_i = theta + q for
  R, d_i = d + q for P. Its limits and home value are ``min_deg``, ``max_deg``, ``home_deg``
  for R and ``min_mm``, ``max_mm``, ``home_mm`` for P (leave the other unit's cells empty).
  ``home`` defaults to 0 if inside the limits, else to their middle.
* The ``site`` section gives positions in the flange frame: ``tool`` (required; optional
  orientation ``R = Rz(rz) Ry(ry) Rx(rx)``), one or more reflectors ``target_<id>``
  (points: no rotation), and optionally ``base``: the pose of frame 0 in the world.

Bad input raises ``DHTableError`` (a ValueError) naming the file, line and column.
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
from pathlib import Path

from twin.exceptions import ModelError
from twin.formats.dh import DHJoint, DHSite, DHTable, DHTableError
from twin.formats.dh_mjcf import build_parameters, build_xml
from twin.formats.model_files import out_files, write_model_files
from twin.formats.parameter_file import closest, read_utf8

CONVENTIONS = ("standard", "modified")
JOINT_REQUIRED = ("joint", "alpha_deg", "a_mm", "d_mm", "theta_deg", "min_deg", "max_deg")
JOINT_OPTIONAL = ("type", "home_deg", "min_mm", "max_mm", "home_mm")
SITE_REQUIRED = ("site", "x_mm", "y_mm", "z_mm")
SITE_OPTIONAL = ("rx_deg", "ry_deg", "rz_deg")
_CONVENTION = re.compile(r"#\s*convention\s*:\s*(.*)$", re.IGNORECASE)
_TARGET = re.compile(r"target_[A-Za-z0-9_]+$")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*$")


class _Reader:
    """Cell access with errors that name file, line and column."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, line: int, message: str, column: str | None = None) -> DHTableError:
        where = f"{self.source}, line {line}" + (f", column '{column}'" if column else "")
        return DHTableError(f"{where}: {message}")

    def header(self, line: int, cells: list[str], required, optional) -> dict[str, int]:
        seen: dict[str, int] = {}
        for k, c in enumerate(cells):
            key = c.strip().lower()
            if key in seen:
                raise self.fail(line, f"column '{key}' appears twice in the header")
            if key not in required + optional:
                hint = closest(key, required + optional)
                raise self.fail(
                    line,
                    f"unknown column '{c}'{hint}; columns are "
                    f"{list(required)} and optionally {list(optional)}",
                )
            seen[key] = k
        missing = [c for c in required if c not in seen]
        if missing:
            raise self.fail(line, f"missing column(s) {missing} in header {cells}")
        return seen

    def number(self, line: int, row: dict[str, str], column: str, scale: float) -> float:
        text = row.get(column, "")
        if not text:
            raise self.fail(line, "empty cell, a number is required", column)
        try:
            value = float(text)
        except ValueError:
            raise self.fail(line, f"'{text}' is not a number", column) from None
        if not math.isfinite(value):
            raise self.fail(line, f"'{text}' is not a finite number", column)
        return value * scale


def _joint(r: _Reader, line: int, row: dict[str, str]) -> DHJoint:
    kind = (row.get("type") or "R").upper()
    if kind not in ("R", "P"):
        raise r.fail(line, f"type '{row['type']}' is neither R nor P", "type")
    unit, other, scale = ("deg", "mm", math.pi / 180) if kind == "R" else ("mm", "deg", 1e-3)
    for c in ("min", "max", "home"):
        if row.get(f"{c}_{other}"):
            raise r.fail(
                line,
                f"a {kind} joint's {c} is given in {c}_{unit}, leave this cell empty",
                f"{c}_{other}",
            )
    lo = r.number(line, row, f"min_{unit}", scale)
    hi = r.number(line, row, f"max_{unit}", scale)
    if not lo < hi:
        raise r.fail(
            line, f"min {row[f'min_{unit}']} must be below max {row[f'max_{unit}']}", f"max_{unit}"
        )
    if row.get(f"home_{unit}"):
        home = r.number(line, row, f"home_{unit}", scale)
        if not lo <= home <= hi:
            raise r.fail(line, "home lies outside [min, max]", f"home_{unit}")
    else:
        home = 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
    deg, mm = math.pi / 180, 1e-3
    return DHJoint(
        row["joint"],
        kind,
        r.number(line, row, "alpha_deg", deg),
        r.number(line, row, "a_mm", mm),
        r.number(line, row, "d_mm", mm),
        r.number(line, row, "theta_deg", deg),
        lo,
        hi,
        home,
    )


def _site(r: _Reader, line: int, row: dict[str, str]) -> DHSite:
    name = row["site"]
    pos = tuple(r.number(line, row, c, 1e-3) for c in ("x_mm", "y_mm", "z_mm"))
    rpy = tuple(r.number(line, row, c, math.pi / 180) if row.get(c) else 0.0 for c in SITE_OPTIONAL)
    if name.startswith("target_") and any(rpy):
        bad = next(c for c, v in zip(SITE_OPTIONAL, rpy, strict=True) if v)
        raise r.fail(line, f"reflector '{name}' is a point: leave its rotation empty", bad)
    return DHSite(name, pos, rpy)  # type: ignore[arg-type]


def parse_dh_table(text: str, source: str = "<table>") -> DHTable:
    """Read the CSV text of a DH table (format in the module docstring)."""
    r = _Reader(source)
    convention: str | None = None
    columns: dict[str, int] | None = None
    section = None
    joints: list[DHJoint] = []
    sites: dict[str, DHSite] = {}
    for n, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if stripped.startswith("#"):
            m = _CONVENTION.match(stripped)
            if m and section is not None:
                raise r.fail(n, "the convention line must come before the joint header")
            if m and convention is not None:
                raise r.fail(n, "the convention is given twice")
            if m:
                convention = m.group(1).strip().lower()
                if convention not in CONVENTIONS:
                    raise r.fail(
                        n,
                        f"unknown convention '{m.group(1).strip()}'"
                        f"{closest(convention, CONVENTIONS)}; use one of {CONVENTIONS}",
                    )
            continue
        if not stripped:
            continue
        cells = [c.strip() for c in next(csv.reader([raw]))]
        first = cells[0].lower()
        if section is None:
            if convention is None:
                raise r.fail(n, "no '# convention: standard|modified' line before the table")
            if first != "joint":
                raise r.fail(n, f"expected the joint header {','.join(JOINT_REQUIRED)}")
            columns, section = r.header(n, cells, JOINT_REQUIRED, JOINT_OPTIONAL), "joint"
            continue
        if first == "site" and section == "joint":
            columns, section = r.header(n, cells, SITE_REQUIRED, SITE_OPTIONAL), "site"
            continue
        assert columns is not None
        if len(cells) > len(columns):
            raise r.fail(n, f"{len(cells)} cells for {len(columns)} columns")
        row = {c: (cells[k] if k < len(cells) else "") for c, k in columns.items()}
        key = "joint" if section == "joint" else "site"
        name = row[key]
        if not _NAME.match(name):
            raise r.fail(n, f"'{name}' is not a valid name (letters, digits, _ . -)", key)
        if section == "joint":
            if any(j.name == name for j in joints):
                raise r.fail(n, f"duplicate joint name '{name}'", "joint")
            joints.append(_joint(r, n, row))
        else:
            if name in sites:
                raise r.fail(n, f"duplicate site '{name}'", "site")
            if name not in ("tool", "base") and not _TARGET.match(name):
                raise r.fail(n, f"unknown site '{name}': use tool, base or target_<id>", "site")
            sites[name] = _site(r, n, row)
    if convention is None:
        raise DHTableError(f"{source}: no '# convention: standard|modified' line")
    if not joints:
        raise DHTableError(f"{source}: no joint rows")
    if "tool" not in sites:
        raise DHTableError(f"{source}: no 'tool' row in the site section")
    targets = tuple(s for k, s in sites.items() if k.startswith("target_"))
    if not targets:
        raise DHTableError(f"{source}: no reflector row 'target_<id>' in the site section")
    base = sites.get("base", DHSite("base", (0.0, 0.0, 0.0)))
    return DHTable(convention, tuple(joints), sites["tool"], targets, base, source)


def read_dh_table(path: str | Path) -> DHTable:
    path = Path(path)
    try:
        text = read_utf8(path)
    except (OSError, UnicodeError) as exc:
        raise DHTableError(f"{path}: cannot read: {exc}") from None
    return parse_dh_table(text, source=str(path))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="pkm-calib from-dh", description=__doc__.split("\n")[0])
    ap.add_argument("table", help="DH table (CSV)")
    ap.add_argument("--name", required=True, help="model name: NAME.xml, NAME.params.toml")
    ap.add_argument("--out-dir", default=".", help="where to write (default: .)")
    ap.add_argument("--targets", help="comma-separated reflectors to keep (default: all)")
    ap.add_argument(
        "--no-target-errors",
        action="store_true",
        help="leave the reflectors' site_pos errors out of the error model",
    )
    ap.add_argument(
        "--base-errors",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="base.dx..base.rz, the base's placement in the world, in the error model (the "
        "default: for readings in the base frame nothing else absorbs it; for tracker-frame "
        "readings identify finds them redundant with the registration and fixes them); "
        "--no-base-errors leaves them out",
    )
    ap.add_argument(
        "--force", action="store_true", help="replace existing NAME.xml, NAME.params.toml"
    )
    args = ap.parse_args(argv)
    if not _NAME.match(args.name):
        ap.error(f"--name '{args.name}' is not a valid name")
    try:
        table = read_dh_table(args.table)
        if args.targets:
            table = table.with_targets([t.strip() for t in args.targets.split(",")])
    except DHTableError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = [f"{args.name}.xml", f"{args.name}.params.toml"]
    try:
        xml, toml = out_files(args.out_dir, names, args.force)
    except ModelError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    params = build_parameters(table, args.name, not args.no_target_errors, args.base_errors)
    if not write_model_files({xml: build_xml(table, args.name), toml: params}):  # both or none
        return 2
    print(f"wrote {xml} and {toml}")
    return 0


dh_table_command = main  # pkm-calib from-dh (pkm_calib.command)

if __name__ == "__main__":
    raise SystemExit(main())
