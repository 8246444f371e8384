"""Print the configuration reference generated from the schema, or write it into the README.

    .venv/bin/python scripts/config_reference.py                  # print the Markdown tables
    .venv/bin/python scripts/config_reference.py --write README.md  # replace the README's block

The tables come from :mod:`station.config.reference` (every key, type, unit, default and range, as
declared beside the fields and in each driver's ``SETTINGS``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from station.config.reference import markdown, with_reference


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--write", type=Path, metavar="README", help="replace the block between the README's markers")
    args = p.parse_args(argv)
    if args.write is None:
        sys.stdout.write(markdown())
        return 0
    args.write.write_text(with_reference(args.write.read_text(encoding="utf-8")), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
