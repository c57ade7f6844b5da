"""Write the measured numbers of the README and of docs/ from the committed JSON records.

    python docs/build.py            # rewrite every generated table and value in place
    python docs/build.py --check    # exit 1 if a page differs from what its records give

A page marks a generated table as::

    <!-- table: NAME -->
    ...
    <!-- /table -->

and a generated number inside a sentence as ``<!-- value: NAME -->...<!-- /value -->``; NAME is
a key of :data:`TABLES` or :data:`VALUES` (functions of the records in ``docs/tables.py``).
Nothing between the markers is written by hand: the records are written by the committed
benchmark and experiment scripts, and this script turns them into text.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from tables import TABLES, VALUES

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
TABLE = re.compile(r"(<!-- table: (?P<name>[\w.-]+) -->\n)(?P<body>.*?)(<!-- /table -->)", re.S)
VALUE = re.compile(r"(<!-- value: (?P<name>[\w.-]+) -->)(?P<body>.*?)(<!-- /value -->)")
OPENING = re.compile(r"<!-- value: (?P<name>[\w.-]+) -->")


def render(text: str, page: Path) -> str:
    """``text`` with every generated table and value written from the records."""

    def table(match: re.Match) -> str:
        name = match["name"]
        if name not in TABLES:
            raise SystemExit(f"{page.name}: unknown table {name!r}")
        return match[1] + TABLES[name]().rstrip("\n") + "\n" + match[4]

    def value(match: re.Match) -> str:
        name = match["name"]
        if name not in VALUES:
            raise SystemExit(f"{page.name}: unknown value {name!r}")
        return match[1] + VALUES[name]() + match[4]

    opened = [m["name"] for m in OPENING.finditer(text)]
    closed = [m["name"] for m in VALUE.finditer(text)]
    if opened != closed:
        unclosed = sorted(set(opened) - set(closed)) or opened
        raise SystemExit(f"{page.name}: value marker {unclosed[0]!r} is not closed on its own line by <!-- /value -->")
    return VALUE.sub(value, TABLE.sub(table, text))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check that the pages are current")
    args = parser.parse_args(argv)
    stale = []
    for page in PAGES:
        text = page.read_text()
        new = render(text, page)
        if new != text:
            stale.append(page)
            if not args.check:
                page.write_text(new)
    if args.check and stale:
        names = ", ".join(str(p.relative_to(ROOT)) for p in stale)
        print(f"out of date with their records: {names} (run python docs/build.py)", file=sys.stderr)
        return 1
    print("checked" if args.check else "wrote", len(PAGES), "pages")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
