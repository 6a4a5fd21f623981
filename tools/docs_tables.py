"""Regenerate the tables in docs/*.md from the benchmark JSON in bench_results/.

    .venv/bin/python tools/docs_tables.py           # rewrite every generated table in docs/
    .venv/bin/python tools/docs_tables.py --check   # exit 1, naming each table that differs

A generated table sits between two comments that say which commands print it:

    <!-- generated from: python -m lab bench --method ground-truth --report --out R -->
    ...
    <!-- end of generated table -->

Each command is a ``python -m lab`` command line that reads JSON only (``--report``), run
here in this process; several commands are joined with `` ; `` and their tables merged into
one (rows of the same header). Nothing but the JSON files feeds a table, so running this twice
changes nothing, and the docs cannot drift from the data without ``--check`` failing.
"""

import argparse
import contextlib
import io
import re
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
REGION = re.compile(r"(<!-- generated from: (?P<commands>.+?) -->\n)(?P<body>.*?)"
                    r"(<!-- end of generated table -->)", re.S)
PREFIX = ["python", "-m", "lab"]


def run_lab(command: str) -> str:
    """The standard output of one ``python -m lab ...`` command, run in this process."""
    words = shlex.split(command)
    if words[:3] != PREFIX:
        raise ValueError(f"not a 'python -m lab' command: {command}")
    sys.path.insert(0, str(ROOT))
    from lab.__main__ import main

    printed = io.StringIO()
    with contextlib.chdir(ROOT), contextlib.redirect_stdout(printed), \
            contextlib.redirect_stderr(io.StringIO()) as errors:
        status = main(words[3:])
    if status != 0 or "missing" in errors.getvalue() or "not run" in printed.getvalue():
        raise RuntimeError(f"{command} did not find all of its results:\n{errors.getvalue()}"
                           f"{printed.getvalue()}")
    return printed.getvalue()


def merged(outputs) -> str:
    """Several commands' tables as one: the first output whole, the others' rows after it
    (their headers, identical, left out)."""
    lines = outputs[0].strip().splitlines()
    for output in outputs[1:]:
        lines += [line for line in output.strip().splitlines()
                  if line.startswith("|") and line not in lines]
    return "\n".join(lines) + "\n"


def regenerate(text: str) -> str:
    """``text`` with every generated region's body replaced by its commands' output."""
    def body(match):
        outputs = [run_lab(command.strip()) for command in match["commands"].split(" ; ")]
        return match.group(1) + "\n" + merged(outputs) + "\n" + match.group(4)

    return REGION.sub(body, text)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="change nothing; exit 1 if a generated table differs from the data")
    parser.add_argument("files", nargs="*", type=Path, default=sorted(DOCS.glob("*.md")),
                        help="markdown files (default docs/*.md)")
    args = parser.parse_args(argv)
    stale = []
    for path in args.files:
        text = path.read_text(encoding="utf-8")
        new = regenerate(text)
        if new == text:
            continue
        stale.append(path)
        if not args.check:
            path.write_text(new, encoding="utf-8")
    for path in stale:
        verb = "differs from bench_results/" if args.check else "updated"
        shown = path.resolve().relative_to(ROOT) if path.resolve().is_relative_to(ROOT) else path
        print(f"{shown}: generated tables {verb}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
