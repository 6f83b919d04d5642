"""Say what the test run skipped, and fail when a test that guards a promise was skipped
for a reason not allowed in .ci/skips.toml.

Usage: python .ci/check_skips.py <pytest junit XML> [skips.toml]
Exit 0: every skip listed (one line each, with its reason); 1: a guarded test skipped
without an allowed reason (each named); 2: the XML is missing or unreadable."""

from __future__ import annotations

import sys
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent


def skipped(junit: Path) -> list[tuple[str, str]]:
    """(test id, reason) of every skipped test case in a pytest junit XML."""
    out = []
    for case in ET.parse(junit).getroot().iter("testcase"):
        for skip in case.findall("skipped"):
            if skip.get("type") == "pytest.xfail":  # an expected failure ran: not a skip
                continue
            module = case.get("classname", "").replace(".", "/")
            reason = skip.get("message", "") or (skip.text or "").strip()
            out.append((f"{module}.py::{case.get('name', '')}", reason))
    return out


def _reason_text(reason: str) -> str:
    """The reason pytest gave, without its 'file:line: ' prefix (junit keeps it)."""
    return reason.split(": ", 1)[1] if reason.startswith(("/", "tests/")) else reason


def check(junit: Path, rules_path: Path) -> int:
    rules = tomllib.loads(rules_path.read_text())
    guarded = [g["test"] for g in rules.get("guarded", [])]
    allowed = {a["reason"]: a["why"] for a in rules.get("allowed", [])}
    skips = skipped(junit)
    bad = []
    print(f"{len(skips)} test(s) skipped")
    for test, reason in skips:
        guard = next((g for g in guarded if test.startswith(g) or f"/{g}" in test), None)
        why = next((w for r, w in allowed.items() if r in reason), None)
        mark = ""
        if guard is not None:
            mark = f"  [guards a promise; allowed: {why}]" if why else "  [guards a promise]"
            if why is None:
                bad.append((test, reason))
        print(f"SKIPPED {test}: {_reason_text(reason)}{mark}")
    for test, reason in bad:
        print(
            f"FAILED: {test} guards a promise and was skipped ({_reason_text(reason)}); "
            f"run it where it can run, or name the reason in {rules_path.name}",
            file=sys.stderr,
        )
    return 1 if bad else 0


def main(argv: list[str]) -> int:
    if not argv or len(argv) > 2:
        print(__doc__, file=sys.stderr)
        return 2
    junit = Path(argv[0])
    rules = Path(argv[1]) if len(argv) == 2 else HERE / "skips.toml"
    try:
        return check(junit, rules)
    except (OSError, ET.ParseError, tomllib.TOMLDecodeError, KeyError) as exc:
        print(f"cannot check the skips: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
