"""Write the numpy ↔ GLSL mirror table (precompute/shading/mirror.py) into docs/ARCHITECTURE.md.

    .venv/bin/python scripts/mirror_table.py          # rewrites the table between its markers
    .venv/bin/python scripts/mirror_table.py --check  # exit 1 if the page shows another table

tests/test_mirror.py checks the same.
"""

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from precompute.shading import mirror  # noqa: E402

PAGE = ROOT / "docs" / "ARCHITECTURE.md"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check, write nothing")
    args = parser.parse_args(argv)
    text = PAGE.read_text(encoding="utf-8")
    new = mirror.replace_table(text)
    if new == text:
        print(f"{PAGE.relative_to(ROOT)}: the mirror table is up to date")
        return 0
    if args.check:
        print(f"{PAGE.relative_to(ROOT)}: the mirror table differs from precompute/shading/mirror.py")
        return 1
    PAGE.write_text(new, encoding="utf-8")
    print(f"{PAGE.relative_to(ROOT)}: the mirror table rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
