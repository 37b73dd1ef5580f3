"""Run every benchmark and rewrite docs/BENCHMARKS.md (``make bench``).

Usage: ``python -m benchmarks.run [--only SECTION ...]``. Suites are generated on first use and
cached (see ``ipr_shapes.suites``); figures are medians over each suite's scenes. Each section sits
between ``<!-- section: NAME -->`` and ``<!-- end section: NAME -->`` in the page; ``--only``
reruns the named sections and keeps the others as the page has them (a section the page lacks
is appended). The inference section keeps each of its runs on disk (``benchmarks.inference_run``):
rerunning it on unchanged code only rescores and rerenders them.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from benchmarks import foundation, hypothesis_ceiling, inference, replay, segmentation
from benchmarks.common import machine_description

SECTIONS = {
    "foundation": foundation.run,
    "segmentation": segmentation.run,
    "hypotheses": hypothesis_ceiling.run,
    "inference": inference.run,
    "replay": replay.run,
}
OUTPUT = Path(__file__).resolve().parents[1] / "docs" / "BENCHMARKS.md"


def code_version() -> str:
    """The checked-out commit (short hash; "+changes" when the tree differs from it outside
    docs/, which the benchmarks themselves write)."""
    root = OUTPUT.parents[1]
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs"],
            cwd=root, capture_output=True, text=True,
        ).stdout.strip()  # fmt: skip
    except OSError:
        return "unknown"
    return (commit or "unknown") + ("+changes" if dirty else "")


def marked(name: str, text: str) -> str:
    """A section's text between its markers, with when and from which commit it was run."""
    stamp = f"_Section run on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC at commit {code_version()}._"
    return f"<!-- section: {name} -->\n{text.rstrip()}\n\n{stamp}\n<!-- end section: {name} -->\n"


def kept_sections(page: str) -> dict[str, str]:
    """Name -> marked text of every section of an existing page."""
    pattern = re.compile(r"<!-- section: (\w+) -->\n.*?<!-- end section: \1 -->\n", re.S)
    return {match.group(1): match.group(0) for match in pattern.finditer(page)}


def main(argv: list[str] | None = None) -> int:
    """Generate suites, run the selected sections, write the page atomically."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--only", nargs="*", choices=sorted(SECTIONS), help="sections to run")
    args = parser.parse_args(argv)
    from ipr_shapes.suites import SUITES, suite_scenes

    started = time.perf_counter()
    suites = {}
    for name in SUITES:
        print(f"bench: suite {name} ...", flush=True)
        suites[name] = suite_scenes(name)
    parts = [
        "# Benchmarks",
        "",
        f"Written by `make bench` on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.",
        f"Machine: {machine_description()}.",
        "",
    ]
    previous = kept_sections(OUTPUT.read_text(encoding="utf-8")) if OUTPUT.exists() else {}
    for name, section in SECTIONS.items():
        if args.only and name not in args.only:
            if name in previous:
                parts.append(previous[name])
            continue
        print(f"bench: {name} ...", flush=True)
        parts.append(marked(name, section(suites)))
    parts.append(f"_Total benchmark time: {time.perf_counter() - started:.0f} s._\n")
    staging = OUTPUT.with_suffix(".md.tmp")
    staging.write_text("\n".join(parts), encoding="utf-8")
    staging.replace(OUTPUT)
    print(f"bench: wrote {OUTPUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
