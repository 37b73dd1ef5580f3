"""Run every benchmark and rewrite docs/BENCHMARKS.md (``make bench``).

Usage: ``python -m benchmarks.run [--only SECTION ...]``. Suites are generated on first use and
cached (see ``ipr.suites``); figures are medians over each suite's scenes.
"""

from __future__ import annotations

import argparse
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import ipr  # noqa: F401  (GL backend before MuJoCo loads)
from benchmarks import foundation, inference, segmentation
from benchmarks.common import machine_description

SECTIONS = {
    "foundation": foundation.run,
    "segmentation": segmentation.run,
    "inference": inference.run,
}
OUTPUT = Path(__file__).resolve().parents[1] / "docs" / "BENCHMARKS.md"


def main(argv: list[str] | None = None) -> int:
    """Generate suites, run the selected sections, write the page atomically."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--only", nargs="*", choices=sorted(SECTIONS), help="sections to run")
    args = parser.parse_args(argv)
    from ipr.suites import SUITES, suite_scenes

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
    for name, section in SECTIONS.items():
        if args.only and name not in args.only:
            continue
        print(f"bench: {name} ...", flush=True)
        parts.append(section(suites))
    parts.append(f"_Total benchmark time: {time.perf_counter() - started:.0f} s._\n")
    staging = OUTPUT.with_suffix(".md.tmp")
    staging.write_text("\n".join(parts), encoding="utf-8")
    staging.replace(OUTPUT)
    print(f"bench: wrote {OUTPUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
