"""The benchmark page keeps the sections a partial run (``--only``) did not rerun."""

from __future__ import annotations

from benchmarks.run import kept_sections, marked


def test_sections_are_found_again_with_their_stamps():
    page = (
        "# Benchmarks\n\n" + marked("foundation", "## A\n\n| x |\n") + marked("inference", "## B")
    )
    sections = kept_sections(page + "_Total benchmark time: 1 s._\n")
    assert list(sections) == ["foundation", "inference"]
    assert sections["foundation"].startswith("<!-- section: foundation -->\n## A")
    assert "| x |" in sections["foundation"] and "## B" not in sections["foundation"]
    assert "_Section run on " in sections["inference"] and "at commit " in sections["inference"]
    # A page written before the markers existed has no sections to keep.
    assert kept_sections("# Benchmarks\n\n## A\n") == {}
